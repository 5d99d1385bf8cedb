"""An edge (a server started with --zenoh, in-process, over a simulated quad) seen from a
plain Zenoh session on loopback (peer mode, explicit endpoints, no multicast): its
liveliness tokens, its states at both tiers in the API's schema, events, messages, stream
health, and REST calls run through its api queryable with every REST check."""

from __future__ import annotations

import asyncio
import itertools
import json
import socket
import statistics
import threading
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Any

import httpx
import pytest
import pytest_asyncio
import zenoh

from server.fleet.edge import EdgeService, default_edge_name
from server.fleet.keys import FleetKeys
from server.fleet.session import open_session
from server.fleet.view_service import FleetService
from server.http.schemas import VehicleStateOut
from sim.process.runner import SimCluster
from tests.api.conftest import (
    OBSERVER,
    PILOT,
    SIM_SPEED,
    Api,
    api_at,
    app_running,
    auth,
    make_settings,
    sim_cluster,
)
from tests.fleet.fake_edge import free_tcp_endpoint, loopback_options
from tests.waiting import eventually, holds_for, wait_for

pytestmark = pytest.mark.asyncio(loop_scope="module")

FLEET = "edgetest"
EDGE = "edge-t"
KEYS = FleetKeys(FLEET)
HOLD_STILL = {"type": "velocity_ned", "north_m_s": 0.0, "east_m_s": 0.0, "down_m_s": 0.0}


@dataclass
class Seen:
    """Everything the watching session received, with the monotonic time it came."""

    samples: list[tuple[float, str, dict[str, Any]]] = field(default_factory=list)
    alive: dict[str, bool] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def on_sample(self, sample: zenoh.Sample) -> None:
        payload = json.loads(sample.payload.to_bytes())
        with self.lock:
            self.samples.append((time.monotonic(), str(sample.key_expr), payload))

    def on_alive(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.alive[str(sample.key_expr)] = sample.kind == zenoh.SampleKind.PUT

    def on(self, leaf: str, vehicle_id: int = 1) -> list[tuple[float, dict[str, Any]]]:
        key = f"{KEYS.prefix}/{EDGE}/{vehicle_id}/{leaf}"
        with self.lock:
            return [(t, p) for t, k, p in self.samples if k == key]

    def is_alive(self, key: str) -> bool:
        with self.lock:
            return self.alive.get(key, False)


@dataclass
class Rig:
    api: Api
    sim: SimCluster
    session: zenoh.Session
    seen: Seen
    late_port: int  # where the server looks for a vehicle that is not there yet
    endpoint: str  # where the edge listens

    @property
    def edge(self) -> EdgeService:
        edge: EdgeService = self.api.app.state.edge
        return edge

    async def call(
        self, method: str, path: str, *, token: str | None = PILOT,
        lease: str | None = None, body: Any = None, raw: bytes | None = None,
    ) -> dict[str, Any]:
        """A query to the edge's api queryable; its one reply payload."""
        headers = {}
        if token is not None:
            headers["authorization"] = f"Bearer {token}"
        if lease is not None:
            headers["x-lease-id"] = lease
        request = {"method": method, "path": path, "headers": headers, "body": body}
        payload = raw if raw is not None else json.dumps(request).encode()

        def query() -> list[bytes]:
            replies = self.session.get(KEYS.api(EDGE), payload=payload, timeout=30.0)
            return [reply.ok.payload.to_bytes() for reply in replies if reply.ok is not None]

        answers = await asyncio.to_thread(query)
        assert len(answers) == 1, answers
        answer: dict[str, Any] = json.loads(answers[0])
        return answer


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def rig() -> AsyncIterator[Rig]:
    """The edge over one simulated quad (vehicle 1), also linked to a port where a second
    vehicle comes later; the watching session subscribed to everything of the edge."""
    endpoint = free_tcp_endpoint()
    late_port = free_udp_port()
    seen = Seen()
    async with sim_cluster("quad") as sim:
        urls = [f"udpout:127.0.0.1:{sim.instances[0].api_local_port}",
                f"udpout:127.0.0.1:{late_port}"]
        async with api_at(
            urls[0], sim, connect=urls, zenoh=True, fleet_name=FLEET, edge_name=EDGE,
            zenoh_listen=[endpoint], zenoh_multicast_scouting=False,
        ) as api:
            await api.wait_ready()
            session = await asyncio.to_thread(open_session, loopback_options(connect=[endpoint]))
            try:
                session.declare_subscriber(
                    f"{KEYS.prefix}/{EDGE}/**", zenoh.handlers.Callback(seen.on_sample)
                )
                session.liveliness().declare_subscriber(
                    KEYS.all_alive(), zenoh.handlers.Callback(seen.on_alive), history=True
                )
                yield Rig(api, sim, session, seen, late_port, endpoint)
            finally:
                await asyncio.to_thread(session.close)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


async def test_the_default_edge_name_is_the_host_name_as_one_key_chunk() -> None:
    assert default_edge_name("pi-4.local") == "pi-4_local"
    assert default_edge_name("x" * 80) == "x" * 64
    assert default_edge_name("") != ""


async def test_the_edge_and_its_connected_vehicle_are_alive(rig: Rig) -> None:
    await wait_for(lambda: rig.seen.is_alive(KEYS.edge_alive(EDGE)), 10.0, "edge token")
    await wait_for(lambda: rig.seen.is_alive(KEYS.vehicle_alive(EDGE, 1)), 10.0, "vehicle token")


async def test_states_arrive_at_both_tiers_in_the_apis_schema(rig: Rig) -> None:
    await wait_for(lambda: len(rig.seen.on("state/slow")) >= 4, 15.0, "4 slow samples")
    fast, slow = rig.seen.on("state/fast"), rig.seen.on("state/slow")
    # each tier's rate by the server's own clock (when it sent), as a median: a tick the
    # server skipped while the machine was busy is skipped by design (latest wins), and
    # the bounds still tell 10 Hz from 20 Hz and from the slow tier's 1 Hz
    def sent_intervals(samples: list[tuple[float, dict[str, Any]]]) -> list[float]:
        sent = [payload["sent_unix_s"] for _, payload in samples]
        return [b - a for a, b in itertools.pairwise(sent)]

    fast_intervals, slow_intervals = sent_intervals(fast), sent_intervals(slow)
    assert 0.08 <= statistics.median(fast_intervals) <= 0.25, fast_intervals
    assert 0.8 <= statistics.median(slow_intervals) <= 1.5, slow_intervals
    rest = await rig.api.state()
    for _, payload in fast[-3:] + slow[-2:]:
        assert set(payload) == {"edge", "id", "seq", "sent_unix_s", "state"}
        assert (payload["edge"], payload["id"]) == (EDGE, 1)
        assert abs(payload["sent_unix_s"] - time.time()) < 60.0
        assert set(payload["state"]) == set(rest)
        VehicleStateOut.model_validate(payload["state"])
    # one sequence across both tiers, growing, and larger than any earlier edge run's
    seqs = [p["seq"] for _, p in fast]
    assert seqs == sorted(seqs)
    assert len(set(seqs)) == len(seqs)
    assert seqs[0] > (time.time() - 3600) * 1000
    assert slow[-1][1]["seq"] <= fast[-1][1]["seq"] + 1


async def test_api_queries_are_checked_exactly_as_rest(rig: Rig) -> None:
    read = await rig.call("GET", "/api/v1/vehicles/1", token=OBSERVER)
    assert read["status"] == 200
    assert read["headers"]["content-type"] == "application/json"
    assert read["body"]["id"] == 1
    assert read["body"]["type"] == "QUADROTOR"
    no_token = await rig.call("POST", "/api/v1/vehicles/1/arm", token=None, body={})
    assert no_token["status"] == 401, no_token
    observer = await rig.call("POST", "/api/v1/vehicles/1/arm", token=OBSERVER, body={})
    assert observer["status"] == 403, observer
    no_lease = await rig.call("POST", "/api/v1/vehicles/1/arm", body={})
    assert no_lease["status"] == 423, no_lease
    unknown = await rig.call("GET", "/api/v1/vehicles/9")
    assert unknown["status"] == 404
    assert not (await rig.api.state())["armed"]


async def test_only_api_paths_run_and_malformed_queries_are_answered(rig: Rig) -> None:
    for path in ("/", "/api/v2/vehicles", "/api/v1/../index.html", "/api/v1/%2e%2e/x",
                 "/api/v1/fleet", "/api/v1/vehicles?token=x"):
        answer = await rig.call("GET", path)
        assert answer["status"] == 404, (path, answer)
        assert answer["body"]["detail"]["field"] == "path"
    not_json = await rig.call("GET", "/", raw=b"{not json")
    assert not_json["status"] == 422
    assert not_json["body"]["detail"]["field"] == "payload"
    wrong_method = await rig.call("BREW", "/api/v1/vehicles")
    assert wrong_method["status"] == 422
    assert wrong_method["body"]["detail"]["field"] == "method"


async def test_a_pilot_with_the_lease_flies_through_the_edge(rig: Rig) -> None:
    control = await rig.call("POST", "/api/v1/vehicles/1/control", body={})
    assert control["status"] == 200, control
    lease = control["body"]["lease_id"]
    bad = await rig.call(
        "POST", "/api/v1/vehicles/1/takeoff", lease=lease, body={"altitude_m": "high"}
    )
    assert bad["status"] == 422, bad
    arm = await rig.call("POST", "/api/v1/vehicles/1/arm", lease=lease, body={})
    assert arm["status"] == 200, arm
    assert arm["body"]["command"] == "MAV_CMD_COMPONENT_ARM_DISARM"
    assert arm["body"]["result"] == "ACCEPTED"
    await rig.api.wait_state(lambda s: s["armed"], 10.0, "armed", renew=False)
    # the event went to the fleet as the telemetry socket sends it, with edge and id
    await wait_for(
        lambda: any(p["kind"] == "armed" and p["data"]["armed"] for _, p in rig.seen.on("events")),
        10.0, "the armed event",
    )
    event = next(p for _, p in rig.seen.on("events") if p["kind"] == "armed")
    assert event["type"] == "event"
    assert (event["edge"], event["id"], event["vehicle"]) == (
        EDGE, 1, 1
    )
    # PX4's texts (STATUSTEXT and its events) go to .../messages, in the socket's shapes
    # (either may be lost on the way: the vehicle's link is UDP on a loaded machine)
    def texts() -> list[str]:
        return [p.get("text") or p["data"]["text"] for _, p in rig.seen.on("messages")]

    await wait_for(
        lambda: "Armed by external command" in texts(), 10.0, "PX4's text on arming"
    )
    kinds = {p.get("kind", p["type"]) for _, p in rig.seen.on("messages")}
    assert kinds <= {"statustext", "px4_event"}
    assert not any(p["kind"] in ("statustext", "px4_event") for _, p in rig.seen.on("events"))
    # the vehicle's refusal comes back verbatim: the body REST gives
    refused = await rig.call(
        "POST", "/api/v1/vehicles/1/vtol/transition", lease=lease,
        body={"to": "fixed_wing", "wait": False},
    )
    assert refused["status"] == 409, refused
    direct = await rig.api.client.post(
        "/api/v1/vehicles/1/vtol/transition", json={"to": "fixed_wing", "wait": False},
        headers={"X-Lease-Id": lease},
    )
    assert direct.status_code == 409
    assert set(refused["body"]) == set(direct.json())
    assert refused["body"]["result"] == "FAILED"
    assert refused["body"]["reason"] == direct.json()["reason"]
    disarm = await rig.call("POST", "/api/v1/vehicles/1/disarm", lease=lease, body={})
    assert disarm["status"] == 200, disarm
    rig.api.lease_headers = {"X-Lease-Id": lease}


async def test_stream_health_while_a_stream_runs_and_once_when_it_stops(rig: Rig) -> None:
    lease = rig.api.lease_headers["X-Lease-Id"]
    start = await rig.call(
        "POST", "/api/v1/vehicles/1/offboard/start", lease=lease, body={"setpoint": HOLD_STILL}
    )
    assert start["status"] == 200, start
    await wait_for(
        lambda: sum(p["active"] for _, p in rig.seen.on("stream")) >= 2, 10.0, "2 stream samples"
    )
    stop = await rig.call(
        "POST", "/api/v1/vehicles/1/offboard/stop", lease=lease, body={"then_mode": "HOLD"}
    )
    assert stop["status"] == 200, stop
    await wait_for(
        lambda: not rig.seen.on("stream")[-1][1]["active"], 10.0, "the stream's last sample"
    )
    count = len(rig.seen.on("stream"))
    sample = rig.seen.on("stream")[-2][1]
    assert (sample["edge"], sample["id"]) == (EDGE, 1)
    assert sample["rate_hz"] > 0
    assert sample["sent"] > 0
    await holds_for(
        lambda: len(rig.seen.on("stream")) == count, 1.5, "no stream sample after the last"
    )


async def test_a_vehicle_seen_later_is_published_while_its_link_is_connected(rig: Rig) -> None:
    late_key = KEYS.vehicle_alive(EDGE, 2)
    assert not rig.seen.is_alive(late_key)
    async with SimCluster("quad", instance=1, api_local_port=rig.late_port, speed=SIM_SPEED):
        await wait_for(lambda: rig.seen.is_alive(late_key), 15.0, "the late vehicle's token")
        await wait_for(lambda: rig.seen.on("state/fast", 2), 10.0, "the late vehicle's state")
        payload = rig.seen.on("state/fast", 2)[-1][1]
        assert (payload["id"], payload["state"]["id"]) == (2, 2)
    # its link lost (nothing heard for silence_timeout_s): its token goes, the rest stay
    await wait_for(lambda: not rig.seen.is_alive(late_key), 10.0, "the late token gone")
    assert rig.seen.is_alive(KEYS.vehicle_alive(EDGE, 1))
    assert rig.seen.is_alive(KEYS.edge_alive(EDGE))


async def test_an_ask_for_control_through_the_fleet_waits_for_the_holders_answer(
    rig: Rig,
) -> None:
    """The edge holds an ask for control until the holder answers (up to takeover_ask_s);
    the fleet server waits that long too, not just its usual call timeout (shortened here
    so that the holder answers after it)."""
    holder = await rig.api.client.post(
        "/api/v1/vehicles/1/control",
        json={"takeover": True, "force": True, "client_name": "holder"},
    )
    assert holder.status_code == 200, holder.text
    holder_lease = {"X-Lease-Id": holder.json()["lease_id"]}
    settings = make_settings(
        None, fleet=True, fleet_name=FLEET, zenoh_connect=[rig.endpoint],
        zenoh_listen=[free_tcp_endpoint()], zenoh_multicast_scouting=False,
    )
    async with app_running(settings) as fleet_app, httpx.AsyncClient(
        transport=httpx.ASGITransport(app=fleet_app), base_url="http://fleet",
        headers=auth(), timeout=60.0,
    ) as fleet:
        service: FleetService = fleet_app.state.fleet
        await wait_for(lambda: (e := service.view.edge(EDGE)) is not None and e.alive,
                       10.0, "the edge seen by the fleet server")
        service.query_timeout_s = 1.0
        asking = asyncio.create_task(fleet.post(
            f"/api/v1/fleet/edges/{EDGE}/vehicles/1/control",
            json={"takeover": True, "client_name": "asker"},
        ))

        async def pending_request() -> str | None:
            status = (await rig.api.client.get("/api/v1/vehicles/1/control")).json()
            request = status.get("request")
            return None if request is None else str(request["request_id"])

        request_id = await eventually(pending_request, 10.0, "the ask at the holder")
        # the holder answers once the fleet server's usual timeout is over
        await asyncio.sleep(service.query_timeout_s + 0.5)
        assert not asking.done()
        granted = await rig.api.client.post(
            f"/api/v1/vehicles/1/control/requests/{request_id}", json={"grant": True},
            headers=holder_lease,
        )
        assert granted.status_code == 200, granted.text
        answer = await asyncio.wait_for(asking, 30.0)
        assert answer.status_code == 200, answer.text
        assert "asker" in answer.json()["holder"]
        # the new lease is the one the edge holds now: it flies there
        rig.api.lease_headers = {"X-Lease-Id": answer.json()["lease_id"]}
        renewed = await rig.api.client.put(
            "/api/v1/vehicles/1/control", headers=rig.api.lease_headers
        )
        assert renewed.status_code == 200, renewed.text


async def test_tokens_go_when_the_edge_stops(rig: Rig) -> None:
    assert rig.seen.is_alive(KEYS.vehicle_alive(EDGE, 1))
    await rig.edge.stop()
    await wait_for(lambda: not rig.seen.is_alive(KEYS.edge_alive(EDGE)), 2.0, "edge token gone")
    assert not rig.seen.is_alive(KEYS.vehicle_alive(EDGE, 1))
    # the edge answers nothing any more: the query ends without a reply
    replies = await asyncio.to_thread(
        lambda: list(rig.session.get(KEYS.api(EDGE), payload=b"{}", timeout=1.0))
    )
    assert replies == []
    await rig.edge.stop()  # the lifespan stops it again: idempotent
    assert rig.edge.session is None
