"""The control model over WebSockets on a real uvicorn, flying the simulated vehicle over
UDP: a holder asked for control on its socket grants or denies it, every client sees the
control events, the new holder starts from the flown setpoint while the stream goes on, and
a live input that falls silent brakes the vehicle while the lease stays."""

from __future__ import annotations

import asyncio
import gc
import json
import logging
import math
import time
from collections.abc import AsyncIterator
from typing import Any, Union

import httpx
import pytest
from pydantic import TypeAdapter
from websockets.asyncio.client import ClientConnection, connect

from skyhelm_wire.messages import ControlMessage, TelemetryMessage
from tests.api.conftest import PILOT
from tests.api.test_ws import (
    Served,
    close_code,
    close_reading,
    fly_offboard_at_2_m_s,
    receive_until,
    served,
)
from tests.api.test_ws import receive as receive_any
from tests.waiting import eventually, holds_for, wait_for

DEADMAN_S = 0.5
HERE = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -2.0, "yaw_deg": 0.0}
_SOCKET_MESSAGE: TypeAdapter[Any] = TypeAdapter(Union[ControlMessage, TelemetryMessage])  # noqa: UP007


async def receive(ws: ClientConnection, timeout_s: float = 5.0) -> dict[str, Any]:
    """The next message, which must be one the wire package describes."""
    message = await receive_any(ws, timeout_s)
    _SOCKET_MESSAGE.validate_python(message)
    return message


@pytest.fixture
async def quad() -> AsyncIterator[Served]:
    async with served(takeover_ask_s=10.0, deadman_timeout_s=DEADMAN_S) as s:
        yield s


def _speed(state: dict[str, Any]) -> float:
    velocity = state["velocity_ned"]
    return math.hypot(velocity["north_m_s"], velocity["east_m_s"])


async def _control_events(telemetry: Any, count: int) -> list[dict[str, Any]]:
    return [
        (await receive_until(telemetry, {"type": "event", "kind": "control"}))["data"]
        for _ in range(count)
    ]


async def test_a_holder_grants_a_takeover_on_its_socket(quad: Served) -> None:
    vehicle = quad.api.vehicle()
    async with (
        connect(quad.url("telemetry", vehicle=1, rate_hz=1)) as telemetry,
        connect(quad.url("control", vehicle=1, client_name="tab-1", ttl_s=30)) as first,
    ):
        assert (await receive(first))["holder"] == "pilot · tab-1"
        await first.send(json.dumps({"type": "setpoint", "id": 1, "setpoint": HERE}))
        flown = await receive_until(first, {"id": 1})
        assert flown["status"] == 200
        await wait_for(lambda: vehicle.stream_stats().sent >= 10, 5.0, "the stream to run")

        async with connect(
            quad.url("control", vehicle=1, client_name="tab-2", takeover="true")
        ) as second:
            asked = await receive_until(first, {"type": "takeover_requested"})
            assert asked["by"] == "pilot · tab-2"
            assert asked["timeout_s"] == 10.0
            answer = {"type": "takeover_answer", "id": 2, "request_id": asked["request_id"]}
            await first.send(json.dumps({**answer, "grant": True}))
            assert (await receive_until(first, {"id": 2}))["status"] == 200
            told = await receive_until(first, {"type": "lease"})
            assert told == {"type": "lease", "state": "taken_over", "by": "pilot · tab-2"}
            assert await close_code(first) == 4408

            lease = await receive(second)
            assert lease["type"] == "lease"
            assert lease["holder"] == "pilot · tab-2"
            assert lease["taken_from"] == "pilot · tab-1"
            assert lease["setpoint"] == flown["body"]["setpoint"]
            sent_then = vehicle.stream_stats().sent
            await wait_for(
                lambda: vehicle.stream_stats().sent >= sent_then + 10, 5.0, "the stream to go on"
            )
            stats = vehicle.stream_stats()
            assert stats.gaps == 0, stats
            assert stats.max_gap_ms is not None
            assert stats.max_gap_ms <= 2 * 1000.0 / vehicle.stream_rate_hz, stats

        events = await _control_events(telemetry, 5)
    assert [e["action"] for e in events] == [
        "acquired",
        "takeover_requested",
        "takeover_granted",
        "taken_over",
        "acquired",
    ]
    assert (events[3]["holder"], events[3]["previous_holder"]) == ("pilot · tab-2", "pilot · tab-1")


async def test_a_denied_takeover_closes_the_asking_socket(quad: Served) -> None:
    async with connect(quad.url("control", vehicle=1, client_name="tab-1", ttl_s=30)) as first:
        await receive(first)
        async with connect(quad.url("control", vehicle=1, takeover="true")) as second:
            asked = await receive_until(first, {"type": "takeover_requested"})
            deny = {"type": "takeover_answer", "request_id": asked["request_id"], "grant": False}
            await first.send(json.dumps(deny))
            refusal = await receive(second)
            assert refusal == {
                "type": "error",
                "reason": "denied by pilot · tab-1",
                "holder": "pilot · tab-1",
            }
            assert await close_code(second) == 4409
        await first.send(json.dumps({"type": "heartbeat", "id": 9}))
        assert (await receive_until(first, {"id": 9}))["status"] == 200


async def test_the_socket_asks_its_ttl_within_the_bounds(quad: Served) -> None:
    async with connect(quad.url("control", vehicle=1, ttl_s=700)) as refused:
        error = await receive(refused)
        assert (error["type"], error["field"], error["limit"]) == ("error", "ttl_s", 600.0)
        assert await close_code(refused) == 4422
    async with connect(quad.url("control", vehicle=1, ttl_s=5)) as ws:
        lease = await receive(ws)
        assert lease["ttl_s"] == 5.0
        assert lease["session"] == "ws"


async def test_a_silent_live_input_brakes_while_the_lease_stays(quad: Served) -> None:
    async with connect(quad.url("telemetry", vehicle=1, rate_hz=2)) as telemetry:
        ws = await fly_offboard_at_2_m_s(quad)
        north = {"type": "velocity_ned", "north_m_s": 2.0, "east_m_s": 0.0, "down_m_s": 0.0}
        # before the send: the server cannot have it sooner (its answer may come late)
        fed_at = time.monotonic()
        await ws.send(json.dumps({"type": "setpoint", "id": 10, "setpoint": north, "live": True}))
        assert (await receive_until(ws, {"id": 10}))["status"] == 200

        async def stopped_while_heartbeating() -> dict[str, Any] | None:
            # heartbeats keep the lease; they are not live input
            await ws.send(json.dumps({"type": "heartbeat"}))
            state = await quad.api.state()
            return state if _speed(state) < 0.3 else None

        state = await eventually(stopped_while_heartbeating, 10.0, "the brake", poll_s=0.05)
        assert time.monotonic() - fed_at >= DEADMAN_S
        assert state["mode"] == "OFFBOARD"
        assert state["stream"]["active"] is True
        assert state["lease"]["holder"] is not None
        event = await receive_until(telemetry, {"type": "event", "kind": "deadman"})
        assert (event["data"]["action"], event["data"]["cause"]) == ("brake", "live_timeout")
        await close_reading(ws)
        await close_reading(telemetry)


async def test_the_velocity_intent_on_the_socket_is_live_by_default(quad: Served) -> None:
    async with (
        connect(quad.url("telemetry", vehicle=1, rate_hz=1)) as telemetry,
        connect(quad.url("control", vehicle=1, ttl_s=30)) as ws,
    ):
        await receive(ws)
        velocity = {"frame": "ned", "north_m_s": 1.0, "east_m_s": 0.0}
        command = {"type": "command", "id": 1, "name": "velocity", "args": velocity}
        await ws.send(json.dumps(command))
        answer = await receive_until(ws, {"id": 1})
        assert answer["status"] == 200, answer
        assert answer["body"]["live"] is True
        event = await receive_until(telemetry, {"type": "event", "kind": "deadman"})
        assert (event["data"]["action"], event["data"]["cause"]) == ("brake", "live_timeout")

        # not live: the deadman leaves it alone, however long the socket waits
        await ws.send(json.dumps({**command, "id": 2, "args": {**velocity, "live": False}}))
        assert (await receive_until(ws, {"id": 2}))["body"]["live"] is False
        assert not quad.api.app.state.api.deadman.live_watched(1)
        vehicle = quad.api.vehicle()
        flown = vehicle.offboard.setpoint
        await holds_for(
            lambda: vehicle.offboard.setpoint == flown, 3 * DEADMAN_S, "the velocity flown on"
        )


async def test_an_asker_that_closes_its_socket_withdraws_the_request(quad: Served) -> None:
    async with (
        connect(quad.url("telemetry", vehicle=1, rate_hz=1)) as telemetry,
        connect(quad.url("control", vehicle=1, client_name="tab-1", ttl_s=30)) as first,
    ):
        await receive(first)
        async with connect(quad.url("control", vehicle=1, takeover="true")):
            asked = await receive_until(first, {"type": "takeover_requested"})
        withdrawn = await receive_until(
            telemetry, {"type": "event", "kind": "control"}, timeout_s=5.0
        )
        while withdrawn["data"]["action"] != "takeover_withdrawn":
            withdrawn = await receive_until(telemetry, {"type": "event", "kind": "control"})
        grant = {"type": "takeover_answer", "id": 3, "request_id": asked["request_id"]}
        await first.send(json.dumps({**grant, "grant": True}))
        assert (await receive_until(first, {"id": 3}))["status"] == 404
        assert (await quad.api.client.get("/api/v1/vehicles/1/control")).json()[
            "holder"
        ] == "pilot · tab-1"


async def test_a_rest_asker_that_gives_up_withdraws_the_request(quad: Served) -> None:
    control = f"http://{quad.host}/api/v1/vehicles/1/control"
    async with httpx.AsyncClient(headers={"Authorization": f"Bearer {PILOT}"}) as client:
        holder = await client.post(control, json={"client_name": "script", "ttl_s": 30})
        assert holder.status_code == 200
        with pytest.raises(httpx.ReadTimeout):
            await client.post(control, json={"takeover": True}, timeout=0.3)

        async def withdrawn() -> bool:
            return (await client.get(control)).json()["request"] is None

        await eventually(withdrawn, 5.0, "the request withdrawn", poll_s=0.05)
        assert (await client.get(control)).json()["holder"] == "pilot · script"
        audit = await client.get(f"http://{quad.host}/api/v1/control/audit")
        assert audit.json()[-1]["data"]["action"] == "takeover_withdrawn"


async def test_nan_in_a_socket_message_is_a_422_naming_the_field(quad: Served) -> None:
    async with connect(quad.url("control", vehicle=1, ttl_s=30)) as ws:
        await receive(ws)
        await ws.send(
            '{"type": "setpoint", "id": 1, "setpoint": {"type": "velocity_ned",'
            ' "north_m_s": NaN, "east_m_s": 0, "down_m_s": 0}}'
        )
        refused = await receive_until(ws, {"id": 1})
        assert refused["status"] == 422
        assert refused["body"]["detail"]["field"] == "setpoint.north_m_s"
        await ws.send('{"type": "heartbeat", "id": Infinity}')
        unanswerable = await receive(ws)
        assert (unanswerable["id"], unanswerable["status"]) == (None, 422)
        assert unanswerable["body"]["detail"]["field"] == "id"
        await ws.send(json.dumps({"type": "heartbeat", "id": 2}))
        assert (await receive_until(ws, {"id": 2}))["status"] == 200


async def test_a_client_gone_with_answers_in_flight_ends_quietly(
    quad: Served, caplog: pytest.LogCaptureFixture
) -> None:
    """Answers that can no longer be sent (the client closed its socket while its commands
    ran) end without an error in the server's log; the lease goes with the socket."""
    caplog.set_level(logging.ERROR)
    for _ in range(3):
        async with connect(quad.url("control", vehicle=1, ttl_s=30)) as ws:
            await receive(ws)
            for request_id in range(20):
                hold = {"type": "command", "id": request_id, "name": "hold"}
                await ws.send(json.dumps(hold))
                refused = {"type": "command", "id": 100 + request_id, "name": "takeoff",
                           "args": {"altitude_m": "high"}}  # fmt: skip
                await ws.send(json.dumps(refused))

        async def released() -> bool:
            return (await quad.api.client.get("/api/v1/vehicles/1/control")).json()[
                "holder"
            ] is None

        await eventually(released, 5.0, "the lease released", poll_s=0.05)
    await asyncio.sleep(0.5)  # the commands still running when the socket closed end
    gc.collect()  # an exception nobody retrieved is logged when its task is collected
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert errors == []
