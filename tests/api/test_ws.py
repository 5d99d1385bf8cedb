"""WebSockets over a real uvicorn on an ephemeral port: telemetry, the pilot session, and the
deadman when the pilot goes away."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import math
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from server.api.ws_telemetry import ON_CHANGE_KEEPALIVE_S
from server.control.views import CLOCK_FIELDS
from server.link.core.events import VehicleEvent
from tests.api.conftest import (
    OBSERVER,
    PILOT,
    SIM_SPEED,
    Api,
    api_for,
    sim_cluster,
)
from tests.serving import uvicorn_serving
from tests.waiting import eventually, loop_stalls

# The lease of every pilot here whose lease is not under test: these servers share the test's
# loop with the simulated vehicle, and a loaded machine stalls it for longer than a second.
LEASE_TTL_S = 10.0
# The short lease the expiry tests ask for.
TTL_S = 1.0


@dataclass
class Served:
    api: Api
    host: str

    def url(self, path: str, token: str = PILOT, **query: object) -> str:
        params = "&".join(f"{key}={value}" for key, value in {"token": token, **query}.items())
        return f"ws://{self.host}/api/v1/ws/{path}?{params}"


@contextlib.asynccontextmanager
async def served(airframe: str = "quad", **overrides: Any) -> AsyncIterator[Served]:
    settings = {"lease_ttl_s": LEASE_TTL_S, **overrides}
    async with sim_cluster(airframe) as sim, api_for(sim, **settings) as api:
        # real time's margin on PX4's disarm of a vehicle armed and not taken off: 10 s of
        # sim time is 1.25 s of wall time at 8x, and a loop this test shares with the sim
        # stalls longer on a busy machine (the vehicle disarmed between arm and takeoff)
        params = sim.instances[0].vehicle.params
        if params.get("COM_DISARM_PRFLT") > 0:
            params.set("COM_DISARM_PRFLT", params.get("COM_DISARM_PRFLT") * SIM_SPEED)
        await api.wait_ready()
        async with uvicorn_serving(api.app) as host:
            yield Served(api, host)


@pytest.fixture
async def quad() -> AsyncIterator[Served]:
    async with served() as s:
        yield s


async def receive(ws: ClientConnection, timeout_s: float = 5.0) -> dict[str, Any]:
    message: dict[str, Any] = json.loads(await asyncio.wait_for(ws.recv(), timeout_s))
    return message


async def receive_until(
    ws: ClientConnection, want: dict[str, Any], timeout_s: float = 10.0
) -> dict[str, Any]:
    """The first message whose keys include all of `want`'s items."""
    deadline = time.monotonic() + timeout_s
    while True:
        message = await receive(ws, max(0.01, deadline - time.monotonic()))
        if all(message.get(key) == value for key, value in want.items()):
            return message


async def close_reading(ws: ClientConnection) -> None:
    """Closes a socket as a client that keeps reading does. Messages left unread past the
    client's queue stop websockets reading the connection, the server's answer to the close
    among them, and the close then waits out its timeout (10 s)."""

    async def drain() -> None:
        with contextlib.suppress(ConnectionClosed):
            async for _ in ws:
                pass

    reader = asyncio.create_task(drain())
    await ws.close()
    await reader


async def close_code(ws: ClientConnection) -> int | None:
    with contextlib.suppress(ConnectionClosed, TimeoutError):
        while True:
            await asyncio.wait_for(ws.recv(), 5.0)
    return ws.close_code


async def test_telemetry_streams_states_at_the_asked_rate(quad: Served) -> None:
    async with connect(quad.url("telemetry", token=OBSERVER, vehicle=1, rate_hz=5)) as ws:
        first = await receive_until(ws, {"type": "state"})
        assert first["vehicle"] == 1
        assert first["id"] == 1
        assert {
            "mode",
            "armed",
            "landed_state",
            "position_ned",
            "global",
            "stream",
            "lease",
        } <= set(first)
        async with (
            connect(quad.url("telemetry", token=OBSERVER, vehicle=1, rate_hz=5)) as second,
            connect(quad.url("telemetry", token=OBSERVER, vehicle=1, rate_hz=5)) as third,
        ):
            start = time.monotonic()
            begun_s = asyncio.get_running_loop().time()
            async with loop_stalls() as lags_s:
                texts = await asyncio.gather(
                    *(_state_texts(w, start + 2.5, begun_s + 2.0) for w in (ws, second, third))
                )
    # 5 Hz for 2 s: about 10, never the sim's own telemetry rate. Counted by the server's
    # own time of each state (the test shares its loop clock), not by when this client read
    # it: a loaded machine leaves states queued from before the window in the socket. The
    # server, its sim and this test share one loop: the time a busy machine kept it waiting
    # (its wake-ups' lateness) is time no state could be made in, not held against the rate.
    in_window = [
        text for text in texts[0]
        if begun_s <= json.loads(text)["updated_s"] < begun_s + 2.0
    ]
    lost_s = min(2.0, sum(lags_s))
    fewest = max(1, math.floor(5 * (2.0 - lost_s)) - 4)  # 5 on a quiet machine
    assert fewest <= len(in_window) <= 11, (
        lost_s, [json.loads(t)["updated_s"] - begun_s for t in texts[0]])
    # the sockets of one vehicle and rate share each tick: the same text, encoded once (a
    # tick is not known by its updated_s, the time of the vehicle's last message: on a busy
    # machine the server's side of the state can change twice between two of them)
    common = set(texts[0]) & set(texts[1]) & set(texts[2])
    assert len(common) >= len(texts[0]) // 2  # a reader held back may miss one (latest wins)
    publisher = quad.api.app.state.publishers.for_vehicle(quad.api.vehicle(1))
    assert 0 < publisher.encodes <= publisher.ticks


async def _state_texts(ws: ClientConnection, until_s: float,
                       through_updated_s: float = -math.inf) -> list[str]:
    """The state texts read until ``until_s`` and until one taken at or after
    ``through_updated_s`` by the server's clock came (a loaded machine delivers them late)."""
    texts: list[str] = []
    last_updated_s = -math.inf
    while time.monotonic() < until_s or last_updated_s < through_updated_s:
        assert time.monotonic() < until_s + 10.0, "no state taken late enough came"
        text = await asyncio.wait_for(ws.recv(), 5.0)
        assert isinstance(text, str)  # a text frame, as before: the page reads strings
        if text.startswith('{"type":"state"'):
            texts.append(text)
            if through_updated_s > -math.inf:
                last_updated_s = json.loads(text)["updated_s"]
    return texts


async def test_telemetry_carries_events_for_commands_and_lease(quad: Served) -> None:
    async with connect(quad.url("telemetry", vehicle=1, rate_hz=1)) as ws:
        await receive_until(ws, {"type": "state"})
        await quad.api.take_control()
        lease = await receive_until(ws, {"type": "event", "kind": "lease"})
        assert lease["data"]["action"] == "acquired"
        assert (await quad.api.control("mode", {"mode": "POSCTL"})).status_code == 200
        mode = await receive_until(ws, {"type": "event", "kind": "mode"})
        assert mode["vehicle"] == 1


async def test_telemetry_pushes_the_vehicle_list_and_scene_clicks(quad: Served) -> None:
    async with connect(quad.url("telemetry", token=OBSERVER, vehicle=1, rate_hz=1)) as ws:
        listing = await receive_until(ws, {"type": "vehicles"})
        assert [(v["id"], v["type"], v["connected"]) for v in listing["vehicles"]] == [
            (1, "QUADROTOR", True)
        ]
        publishers = quad.api.app.state.publishers
        publishers.publish_click({"seq": 3, "north_m": 1.0, "east_m": 2.0, "lat_deg": 47.4})
        click = await receive_until(ws, {"type": "scene_click"})
        assert (click["seq"], click["east_m"], click["lat_deg"]) == (3, 2.0, 47.4)
        vehicle = quad.api.app.state.api.registry.get(1)
        vehicle.set_connected(False)  # as the link does when the vehicle falls silent
        lost = await receive_until(ws, {"type": "vehicles"})
        assert lost["vehicles"][0]["connected"] is False


async def test_telemetry_refuses_bad_token_foreign_origin_and_impossible_vehicle(
    quad: Served,
) -> None:
    async with connect(quad.url("telemetry", token="wrong-token-123")) as ws:
        assert await close_code(ws) == 4401
    with pytest.raises(InvalidStatus) as foreign:  # refused at the handshake (security.py)
        async with connect(quad.url("telemetry"), origin="http://evil.example"):  # type: ignore[arg-type]
            pass
    assert foreign.value.response.status_code == 403
    async with connect(quad.url("telemetry", vehicle=256)) as ws:  # no MAVLink system id
        assert await close_code(ws) == 4404
    async with connect(quad.url("telemetry"), origin=f"http://{quad.host}") as ws:  # type: ignore[arg-type]
        assert (await receive_until(ws, {"type": "state"}))["vehicle"] == 1


async def test_control_session_gets_lease_and_answers_every_message(quad: Served) -> None:
    async with connect(quad.url("control", vehicle=1, client_name="ws-pilot")) as ws:
        lease = await receive(ws)
        assert lease["type"] == "lease"
        assert lease["ttl_s"] == LEASE_TTL_S
        await ws.send(json.dumps({"type": "heartbeat", "id": 1}))
        assert (await receive(ws))["id"] == 1
        await ws.send(json.dumps({"type": "command", "id": 2, "name": "arm", "args": {}}))
        armed = await receive_until(ws, {"id": 2})
        assert armed["status"] == 200
        assert armed["body"]["result"] == "ACCEPTED"
        await ws.send(json.dumps({"type": "setpoint", "id": 3, "setpoint": {"type": "warp"}}))
        refused = await receive_until(ws, {"id": 3})
        assert refused["status"] == 422
        assert refused["ok"] is False
        await ws.send(json.dumps({"type": "command", "id": 4, "name": "fly_away"}))
        assert (await receive_until(ws, {"id": 4}))["status"] == 422
        await ws.send("not json")
        assert (await receive(ws))["status"] == 422
        state = await quad.api.state()
        assert state["lease"]["holder"] == "pilot · ws-pilot"
        # the WS lease id works for REST control calls too
        rest = await quad.api.client.post(
            "/api/v1/vehicles/1/hold", headers={"X-Lease-Id": lease["lease_id"]}
        )
        assert rest.status_code != 423


async def test_control_socket_refuses_observer_and_second_pilot(quad: Served) -> None:
    async with connect(quad.url("control", token=OBSERVER, vehicle=1)) as ws:
        assert await close_code(ws) == 4403
    async with connect(quad.url("control", vehicle=1, client_name="first", ttl_s=30)) as first:
        await receive(first)
        async with connect(quad.url("control", vehicle=1)) as second:
            refusal = await receive(second)
            assert refusal["holder"] == "pilot · first"
            assert await close_code(second) == 4409
        async with connect(quad.url("control", vehicle=1, takeover="true", force="true")) as third:
            assert (await receive(third))["type"] == "lease"
            lost = await receive_until(first, {"type": "lease"})
            assert lost["state"] == "taken_over"
            assert await close_code(first) == 4408


async def test_silent_pilot_loses_the_lease_after_ttl(quad: Served) -> None:
    # the lease starts once the socket is accepted: after this instant, whatever the
    # machine's load delays in between
    started = time.monotonic()
    async with connect(quad.url("control", vehicle=1, ttl_s=TTL_S)) as ws:
        await receive(ws)
        lost = await receive_until(ws, {"type": "lease"}, timeout_s=TTL_S + 2.0)
        assert lost["state"] == "expired"
        assert time.monotonic() - started >= TTL_S - 0.01
        assert await close_code(ws) == 4408


async def fly_offboard_at_2_m_s(served: Served) -> ClientConnection:
    """A WS pilot takes off, starts offboard flying north at 2 m/s, and keeps heartbeating
    (every 0.25 s, as the page does, also while a command is answered) until it closes."""
    ws = await connect(served.url("control", vehicle=1))
    await receive(ws)
    beating = asyncio.get_running_loop().create_task(_heartbeats(ws))
    _HEARTBEATS.add(beating)
    beating.add_done_callback(_HEARTBEATS.discard)
    for request_id, name, args in (
        (1, "arm", {}),
        (2, "takeoff", {"altitude_m": 4.0}),
    ):
        await ws.send(json.dumps({"type": "command", "id": request_id, "name": name, "args": args}))
        assert (await receive_until(ws, {"id": request_id}))["status"] == 200

    seen: list[dict[str, Any]] = []

    async def heartbeat_then_state() -> dict[str, Any]:
        await ws.send(json.dumps({"type": "heartbeat"}))
        seen[:] = [await served.api.state()]
        return seen[0]

    async def climbed() -> bool:
        return bool((await heartbeat_then_state())["position_ned"]["down_m"] <= -3.0)

    async def at_2_m_s() -> bool:
        return _speed(await heartbeat_then_state()) >= 1.8

    try:
        await eventually(climbed, 20.0, "takeoff", poll_s=0.1)
    except AssertionError as exc:  # what the vehicle was doing instead
        state = seen[0] if seen else {}
        raise AssertionError(f"{exc}: {_summary(state)}") from None
    start = {
        "setpoint": {"type": "velocity_ned", "north_m_s": 2.0, "east_m_s": 0.0, "down_m_s": 0.0}
    }
    await ws.send(json.dumps({"type": "command", "id": 3, "name": "offboard_start", "args": start}))
    assert (await receive_until(ws, {"id": 3}))["status"] == 200
    await eventually(at_2_m_s, 20.0, "reach 2 m/s", poll_s=0.1)
    return ws


_HEARTBEATS: set[asyncio.Task[None]] = set()


async def _heartbeats(ws: ClientConnection) -> None:
    with contextlib.suppress(ConnectionClosed):
        while True:
            await ws.send(json.dumps({"type": "heartbeat"}))
            await asyncio.sleep(0.25)


def _summary(state: dict[str, Any]) -> dict[str, Any]:
    return {key: state.get(key) for key in (
        "mode", "armed", "landed_state", "position_ned", "lease", "stream", "last_heartbeat_age_s")}


def _speed(state: dict[str, Any]) -> float:
    velocity = state["velocity_ned"]
    return math.hypot(velocity["north_m_s"], velocity["east_m_s"])


async def test_deadman_holds_position_when_the_pilot_socket_closes(quad: Served) -> None:
    api = quad.api
    async with connect(quad.url("telemetry", vehicle=1, rate_hz=2)) as telemetry:
        ws = await fly_offboard_at_2_m_s(quad)
        events = api.app.state.api.registry.get(1).subscribe_events()
        async with loop_stalls() as stalls_s:
            await ws.close()
            closed_at = time.time()
            # the close ends the lease at once: the server's own clock says when it braked;
            # the brake itself is physics, which a loaded machine slows down
            deadman = await _next_event(events, "deadman", 5.0)
        # 0.5 s on a quiet machine; this in-process server shares its loop with the simulated
        # vehicle, which a loaded machine makes late by a few tenths more, and with nothing
        # at all while the machine does not run this process (not held against it)
        assert deadman.time_s - closed_at <= 1.0 + max(stalls_s, default=0.0)
        stopped = await api.wait_state(lambda s: _speed(s) < 0.3, 5.0, "speed below 0.3 m/s")
        assert stopped["mode"] == "OFFBOARD"
        assert stopped["stream"]["active"] is True
        event = await receive_until(telemetry, {"type": "event", "kind": "deadman"})
        assert event["data"]["action"] == "hold"
        assert event["data"]["cause"] == "closed"
        assert event["data"]["ok"] is True


async def test_deadman_holds_when_rest_renewals_stop(quad: Served) -> None:
    api = quad.api
    # the flight up to the test under the server's lease TTL (a busy machine can space two
    # renewals by more than a second); the short TTL under test from the last renewal on
    await api.take_control()
    assert (await api.control("arm")).status_code == 200
    assert (await api.control("takeoff", {"altitude_m": 4.0})).status_code == 200
    await api.wait_state(lambda s: s["position_ned"]["down_m"] < -3.0, 20.0, "climb")
    north = {"type": "velocity_ned", "north_m_s": 2.0, "east_m_s": 0.0, "down_m_s": 0.0}
    assert (await api.control("offboard/start", {"setpoint": north})).status_code == 200
    await api.wait_state(lambda s: _speed(s) > 1.8, 10.0, "2 m/s")
    events = api.app.state.api.registry.get(1).subscribe_events()
    renewed = await api.client.put("/api/v1/vehicles/1/control", json={"ttl_s": TTL_S},
                                   headers=api.lease_headers)
    assert renewed.status_code == 200, renewed.text
    async with loop_stalls() as stalls_s:
        last_renewal = time.time()
        # the server's own clock says when the deadman acted; the brake itself is physics,
        # which a loaded machine slows down
        deadman = await _next_event(events, "deadman", TTL_S + 5.0)
    # TTL + 0.5 s on a quiet machine; this in-process server shares its event loop with the
    # simulated vehicle, which a loaded machine makes late by a few tenths more, and with
    # nothing at all while the machine does not run this process (not held against it)
    assert deadman.time_s - last_renewal <= TTL_S + 1.0 + max(stalls_s, default=0.0)
    assert deadman.data["action"] == "hold"
    stopped = await api.wait_state(lambda s: _speed(s) < 0.3, 5.0, "hold", renew=False)
    assert stopped["mode"] == "OFFBOARD"
    assert stopped["lease"]["holder"] is None


async def _next_event(
    queue: asyncio.Queue[VehicleEvent], kind: str, timeout_s: float
) -> VehicleEvent:
    async with asyncio.timeout(timeout_s):
        while True:
            event = await queue.get()
            if event.kind == kind:
                return event


@pytest.mark.parametrize(
    ("policy", "mode"), [("land", "LAND"), ("rtl", "RTL"), ("hold-mode", "HOLD")]
)
async def test_deadman_applies_land_rtl_and_hold_mode_policies(policy: str, mode: str) -> None:
    async with served(on_operator_loss=policy) as s:
        ws = await fly_offboard_at_2_m_s(s)
        await ws.close()
        # the socket's close ends the lease at once; the upper bound only ends a failing run
        # (the timing itself is held by the hold test above)
        state = await s.api.wait_state(lambda st: st["mode"] == mode, TTL_S + 20.0, mode)
        assert state["armed"] is True


async def test_deadman_does_nothing_without_a_stream(quad: Served) -> None:
    async with connect(quad.url("telemetry", vehicle=1, rate_hz=1)) as telemetry:
        async with connect(quad.url("control", vehicle=1)) as ws:
            await receive(ws)
        lease_end = await receive_until(telemetry, {"type": "event", "kind": "lease"})
        while lease_end["data"]["action"] == "acquired":
            lease_end = await receive_until(telemetry, {"type": "event", "kind": "lease"})
        assert lease_end["data"]["action"] == "closed"
        with pytest.raises(TimeoutError):
            await receive_until(telemetry, {"type": "event", "kind": "deadman"}, timeout_s=0.5)


async def test_deadman_continue_policy_keeps_flying_and_says_so() -> None:
    async with served(on_operator_loss="continue") as s:
        async with connect(s.url("telemetry", vehicle=1, rate_hz=2)) as telemetry:
            ws = await fly_offboard_at_2_m_s(s)
            await ws.close()
            event = await receive_until(telemetry, {"type": "event", "kind": "deadman"})
            assert event["data"]["action"] == "continue"
        state = await s.api.state()
        assert state["mode"] == "OFFBOARD"
        assert _speed(state) > 1.5


def _steady(value: Any, clock: Any) -> Any:
    """A state message without the fields views.CLOCK_FIELDS names (nor the lease's expiry)."""
    if not isinstance(value, dict):
        return value
    return {key: _steady(item, clock.get(key, {})) for key, item in value.items()
            if clock.get(key) is not True}


async def test_telemetry_on_change_skips_only_states_that_tell_nothing_new(quad: Served) -> None:
    clock = {**CLOCK_FIELDS, "lease": {"expires_in_s": True}}
    window_s = 3.0
    async with (
        connect(quad.url("telemetry", token=OBSERVER, vehicle=1, rate_hz=10,
                         on_change="true")) as changed,
        connect(quad.url("telemetry", token=OBSERVER, vehicle=1, rate_hz=10)) as every,
    ):
        await receive_until(changed, {"type": "state"})
        await receive_until(every, {"type": "state"})
        until = time.monotonic() + window_s
        sent, all_ticks = await asyncio.gather(_state_texts(changed, until),
                                               _state_texts(every, until))
    sent_states = [json.loads(text) for text in sent]
    ticks = [json.loads(text) for text in all_ticks]
    # a landed vehicle, little changing but the time: a state for each tick that told
    # something new and a keepalive for each ON_CHANGE_KEEPALIVE_S, no more (a loaded machine
    # makes real changes: values that go stale and come back)...
    told_new = sum(1 for a, b in itertools.pairwise(ticks)
                   if _steady(a, clock) != _steady(b, clock))
    keepalives = window_s / ON_CHANGE_KEEPALIVE_S + 1
    assert len(sent_states) <= told_new + keepalives + 1, (len(sent_states), told_new, len(ticks))
    # ... yet one once ON_CHANGE_KEEPALIVE_S have passed since the last: no tick of the socket
    # at the full rate came a tick or more after that between two states sent (by the server's
    # clock, updated_s: a stalled loop delays both sockets alike) ...
    tick_s = 0.1
    times = [s["updated_s"] for s in sent_states]
    for a, b in itertools.pairwise(times):
        overdue = [t["updated_s"] for t in ticks
                   if a + ON_CHANGE_KEEPALIVE_S + tick_s <= t["updated_s"] < b - tick_s / 2]
        assert overdue == [], (a, b, overdue)
    # ... and none of the ticks skipped told anything new
    for tick in ticks:
        before = [s for s in sent_states if s["updated_s"] <= tick["updated_s"]]
        if before:
            assert _steady(before[-1], clock) == _steady(tick, clock), tick["updated_s"]
