"""The fleet as separate processes (rig.py): a fleet server and two edges with a simulated
vehicle each, brokerless (peer) and through a Zenoh router. Through the fleet server alone:
every vehicle listed, one vehicle on each edge armed and flown, an observer refused; an edge
killed shows lost within 2 s and comes back when restarted; the fleet server killed changes
nothing at the edges. One rig per topology, shared by the module's tests, in order."""

from __future__ import annotations

import signal
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import pytest

from tests.api.test_security_routes import READ, REFUSALS, expected
from tests.fleet.rig import EDGES, FLEET, FleetRig, fleet_rig
from tests.waiting import holds_for_blocking, wait_for_blocking

Json = dict[str, Any]
KEYS = [f"{edge}/1" for edge in EDGES]
TAKEOFF_ALT_M = 4.0
OFFSET_NORTH_M = 5.0
# lease ids the flights took, per topology and edge (the later tests fly without them)
LEASES: dict[tuple[str, str], str] = {}


@pytest.fixture(scope="module", params=["peer", "router"])
def rig(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[
    FleetRig
]:
    with fleet_rig(request.param, tmp_path_factory.mktemp(f"fleet-{request.param}")) as r:
        r.wait_alive(KEYS, 60.0)
        yield r


def fleet_state(rig: FleetRig, edge: str) -> Json:
    state: Json = rig.fleet_get(f"/fleet/edges/{edge}/vehicles/1")
    return state


def test_the_fleet_lists_every_edge_and_vehicle(rig: FleetRig) -> None:
    fleet = rig.fleet_get("/fleet", rig.observer)
    assert fleet["fleet"] == FLEET
    assert {e["edge"]: (e["alive"], e["vehicles"]) for e in fleet["edges"]} == {
        edge: (True, [1]) for edge in EDGES
    }

    # a vehicle's token comes with its link; its first state a tick later
    def rows_with_states() -> dict[str, Json] | None:
        rows = {row["key"]: row for row in rig.fleet_get("/fleet/vehicles", rig.observer)}
        return rows if all(rows.get(key, {}).get("connected") for key in KEYS) else None

    rows = wait_for_blocking("a state of every vehicle", rows_with_states, 30.0)
    assert set(rows) == set(KEYS)
    for key, row in rows.items():
        assert row["alive"] is True, key
        assert row["connected"] is True, key
        assert row["type"] is not None, key
        assert 0.0 <= row["age_s"] < 5.0, key
    # the fleet server has no vehicle of its own, and says it is one
    assert rig.http.get(f"{rig.fleet.api}/vehicles", headers=rig.auth()).json() == []
    assert rig.http.get(f"{rig.fleet.api}/config", headers=rig.auth()).json()["fleet"] is True


def position_ned(rig: FleetRig, edge: str) -> Json:
    """The edge's vehicle's position_ned through the fleet; a state without one fails with
    what the state said of itself (seen once after a take-off, six minutes into a whole
    suite's run, when the test waited for a global position and home only)."""
    state = fleet_state(rig, edge)
    position: Json | None = state.get("position_ned")
    told = {name: state.get(name) for name in (
        "connected", "lost_reason", "stale", "mode", "armed", "message_ages_s", "age_s",
        "state_age_s", "updated_s")}  # fmt: skip
    assert position is not None, f"{edge}/1 state without position_ned: {told}"
    return position


def fleet_row(rig: FleetRig, key: str) -> Json:
    row: Json = next(r for r in rig.fleet_get("/fleet/vehicles") if r["key"] == key)
    return row


def fly(rig: FleetRig, edge: str) -> str:
    """Take control, arm, take off, go to OFFBOARD and fly an offset, all through the fleet
    server; the lease id."""

    def call(method: str, path: str, body: Any = None, lease: str | None = None) -> Json:
        answer = rig.via_fleet(method, edge, path, body, lease_id=lease)
        assert answer.status_code == 200, (edge, path, answer.status_code, answer.text)
        result: Json = answer.json()
        return result

    wait_for_blocking(
        f"{edge}/1 ready to arm",
        lambda: (s := fleet_state(rig, edge)).get("global") is not None
        and s.get("home") is not None and s.get("position_ned") is not None,
        60.0,
    )
    lease = call("POST", "control", {"client_name": f"fleet test {edge}"})["lease_id"]
    assert call("POST", "arm", {}, lease)["result"] == "ACCEPTED"
    call("POST", "takeoff", {"altitude_m": TAKEOFF_ALT_M}, lease)
    wait_for_blocking(
        f"{edge}/1 airborne",
        lambda: -position_ned(rig, edge)["down_m"] > TAKEOFF_ALT_M - 1.0,
        60.0,
    )
    start_north_m = position_ned(rig, edge)["north_m"]
    call("POST", "offboard/start", {}, lease)
    answer = call(
        "POST", "intents/offset", {"north_m": OFFSET_NORTH_M, "east_m": 0.0, "up_m": 0.0}, lease
    )
    assert answer["via"] == "setpoint"  # in OFFBOARD: streamed by the edge
    wait_for_blocking(
        f"{edge}/1 flown north",
        lambda: position_ned(rig, edge)["north_m"]
        > start_north_m + OFFSET_NORTH_M - 1.0,
        60.0,
    )
    return str(lease)


def test_flies_a_vehicle_on_each_edge_through_the_fleet_server(rig: FleetRig) -> None:
    with ThreadPoolExecutor(len(EDGES)) as pool:
        leases = dict(zip(EDGES, pool.map(lambda edge: fly(rig, edge), EDGES), strict=True))
    for edge, lease in leases.items():
        LEASES[(rig.topology, edge)] = lease
        # the fleet lists who controls it, as the edge's own API says
        own = rig.http.get(f"{rig.edges[edge].api}/vehicles/1/control", headers=rig.auth())
        holder = own.json()["holder"]
        assert holder.endswith(f"fleet test {edge}")
        wait_for_blocking(
            f"{edge}/1 controller in the fleet",
            lambda: fleet_row(rig, f"{edge}/1")["controller"] == holder,  # noqa: B023
            10.0,
        )
        assert fleet_row(rig, f"{edge}/1")["armed"] is True
        assert fleet_state(rig, edge)["mode"] == "OFFBOARD"


def test_an_observer_reads_through_the_fleet_and_never_flies(rig: FleetRig) -> None:
    edge = EDGES[0]
    read = rig.via_fleet("GET", edge, "stream", token=rig.observer)
    assert read.status_code == 200
    assert read.json()["active"] is True
    refused = rig.via_fleet("POST", edge, "land", {}, token=rig.observer)
    assert refused.status_code == 403
    assert fleet_state(rig, edge)["mode"] == "OFFBOARD"  # nothing happened


# the fleet's routes as tests/api/test_security_routes.py tries a server's: no token,
# observer, pilot without the lease (each flight holds it); a body is valid, as the input is
# checked before the lease
VALID_BODIES: dict[str, Json] = {
    "setpoint": {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -5.0},
}
FLEET_ROUTES = [
    ("GET", "/api/v1/fleet", ""),
    ("GET", "/api/v1/fleet/vehicles", ""),
    ("GET", "/api/v1/fleet/edges/{edge}/vehicles/{vehicle_id}", ""),
    ("GET", "/api/v1/fleet/edges/{edge}/vehicles/{vehicle_id}/{rest:path}", "control"),
    ("POST", "/api/v1/fleet/edges/{edge}/vehicles/{vehicle_id}/{rest:path}", "land"),
    ("PUT", "/api/v1/fleet/edges/{edge}/vehicles/{vehicle_id}/{rest:path}", "setpoint"),
    ("DELETE", "/api/v1/fleet/edges/{edge}/vehicles/{vehicle_id}/{rest:path}", "control"),
]


def test_fleet_routes_refuse_who_may_not_call_them(rig: FleetRig) -> None:
    wrong = []
    for method, template, rest in FLEET_ROUTES:
        path = template.replace("{edge}", EDGES[0]).replace("{vehicle_id}", "1")
        path = path.replace("{rest:path}", rest).removeprefix("/api/v1")
        got = []
        for headers in ({}, rig.auth(rig.observer), rig.auth()):
            body: Json | None = (
                None if method in ("GET", "DELETE") else VALID_BODIES.get(rest, {})
            )
            answer = rig.http.request(method, f"{rig.fleet.api}{path}", json=body,
                                      headers=headers)
            code = answer.status_code
            got.append(code if code in REFUSALS or code >= 500 else READ)
        if tuple(got) != expected(method, template):
            wrong.append(f"{method} {path}: {got} != {expected(method, template)}")
    assert not wrong, "\n".join(wrong)
    # the pilot without the lease asking for it: the edge's 409 (another session holds it)
    asked = rig.via_fleet("POST", EDGES[0], "control", {})
    assert asked.status_code == 409
    assert fleet_state(rig, EDGES[0])["mode"] == "OFFBOARD"


def test_a_frozen_edge_is_lost_within_2_s_and_returns_when_it_thaws(rig: FleetRig) -> None:
    """SIGSTOP: its sockets stay open but it says nothing, as when the network is cut; the
    Zenoh lease (1 s, server/fleet/session.py) drops it."""
    victim = EDGES[1]
    frozen = time.monotonic()
    rig.edges[victim].signal(signal.SIGSTOP)
    try:
        wait_for_blocking(
            f"{victim}/1 lost", lambda: rig.alive()[f"{victim}/1"] is False, 10.0, every_s=0.02
        )
        lost_after_s = time.monotonic() - frozen
    finally:
        rig.edges[victim].signal(signal.SIGCONT)
    print(f"[{rig.topology}] {victim} SIGSTOPped: lost in the fleet after {lost_after_s:.3f} s")
    assert lost_after_s < 2.0
    assert rig.alive()[f"{EDGES[0]}/1"] is True
    thawed = time.monotonic()
    rig.wait_alive([f"{victim}/1"], 30.0)
    print(f"[{rig.topology}] {victim} thawed: alive again after {time.monotonic() - thawed:.3f} s")


def test_a_killed_edge_is_lost_within_2_s_and_returns_when_restarted(rig: FleetRig) -> None:
    victim, survivor = EDGES[1], EDGES[0]
    killed = time.monotonic()
    rig.edges[victim].kill()
    wait_for_blocking(
        f"{victim}/1 lost", lambda: rig.alive()[f"{victim}/1"] is False, 10.0, every_s=0.02
    )
    lost_after_s = time.monotonic() - killed
    print(f"[{rig.topology}] {victim} SIGKILLed: lost in the fleet after {lost_after_s:.3f} s")
    assert lost_after_s < 2.0
    assert rig.alive()[f"{survivor}/1"] is True
    edges = {e["edge"]: e["alive"] for e in rig.fleet_get("/fleet")["edges"]}
    assert edges == {survivor: True, victim: False}
    assert rig.via_fleet("GET", victim, "stream").status_code == 503
    # still listed, with its last state
    assert fleet_state(rig, victim)["alive"] is False
    rig.restart_edge(victim)
    back = time.monotonic()
    rig.wait_alive([f"{victim}/1"], 30.0)
    print(f"[{rig.topology}] {victim} restarted: alive again {time.monotonic() - back:.3f} s "
          "after it printed its URL")
    wait_for_blocking(
        f"{victim}/1 state after the restart",
        lambda: fleet_state(rig, victim)["armed"] is False and fleet_state(rig, victim)["age_s"]
        < 2.0,
        30.0,
    )


def test_a_killed_fleet_server_changes_nothing_at_the_edges(rig: FleetRig) -> None:
    edge = rig.edges[EDGES[0]]
    lease = LEASES[(rig.topology, EDGES[0])]

    def at_edge(path: str) -> Json:
        answer = rig.http.get(f"{edge.api}/vehicles/1{path}", headers=rig.auth())
        assert answer.status_code == 200, answer.text
        result: Json = answer.json()
        return result

    before = at_edge("/stream")
    assert before["active"] is True
    holder = at_edge("/control")["holder"]
    rig.fleet.kill()
    sent_at_kill = at_edge("/stream")["sent"]
    holds_for_blocking(
        "the edge's stream, lease and flight",
        lambda: (stream := at_edge("/stream"))["active"]
        and stream["since_last_ms"] < 1000.0
        and at_edge("/control")["holder"] == holder
        and at_edge("")["mode"] == "OFFBOARD",
        2.0,
        every_s=0.2,
    )
    after = at_edge("/stream")
    assert after["sent"] > sent_at_kill
    # the pilot, now straight at the edge, still holds the vehicle with the same lease
    renewed = rig.http.put(
        f"{edge.api}/vehicles/1/control", json={}, headers=rig.auth(lease_id=lease)
    )
    assert renewed.status_code == 200, renewed.text
