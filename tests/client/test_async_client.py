"""The asyncio client against a live server and the simulated quad: a flight watched on the
telemetry socket, a forced takeover by a second client, and typed refusals."""

from __future__ import annotations

import asyncio
import contextlib

import pytest

from skyhelm_client import (
    AsyncSkyHelm,
    InvalidInput,
    Message,
    NoLease,
    PositionNed,
    Refused,
    VelocityNed,
)
from tests.client.conftest import pilot_url
from tests.serve_process import Served
from tests.waiting import eventually

ALTITUDE_M = 5.0


async def _collect(sky: AsyncSkyHelm, into: list[Message], opened: asyncio.Event) -> None:
    async with contextlib.aclosing(sky.telemetry(rate_hz=5)) as messages:
        async for message in messages:
            opened.set()
            into.append(message)


def _events(messages: list[Message], kind: str) -> list[dict[str, object]]:
    return [m.data["data"] for m in messages if m.type == "event" and m.kind == kind]


async def test_flies_watches_telemetry_and_is_taken_over(served: Served) -> None:
    async with AsyncSkyHelm(pilot_url(served)) as sky, AsyncSkyHelm(pilot_url(served)) as other:
        messages: list[Message] = []
        opened = asyncio.Event()
        watcher = asyncio.create_task(_collect(other, messages, opened))
        try:
            await asyncio.wait_for(opened.wait(), 10)
            await sky.wait_until(lambda s: s.ready_to_fly, timeout_s=30)
            with pytest.raises(NoLease):
                await sky.takeoff(altitude_m=ALTITUDE_M)
            first = await sky.acquire(client_name="async test")

            assert (await sky.arm()).result == "ACCEPTED"
            await sky.takeoff(altitude_m=ALTITUDE_M)
            state = await sky.wait_until(lambda s: s.altitude_m > ALTITUDE_M - 0.5, timeout_s=60)
            here = state.position_ned
            await sky.offboard_start(
                PositionNed(north_m=here.north_m, east_m=here.east_m, down_m=-ALTITUDE_M)
            )
            with pytest.raises(InvalidInput) as too_fast:
                await sky.set_setpoint(VelocityNed(north_m_s=0.0, east_m_s=0.0, down_m_s=9.0))
            assert too_fast.value.status == 422
            assert too_fast.value.limit == 5.0
            flying = VelocityNed(north_m_s=1.0, east_m_s=0.0, down_m_s=0.0)
            await sky.set_setpoint(flying)
            await sky.wait_until(lambda s: s.position_ned.north_m > here.north_m + 1.0, 30)

            second = await other.take_over(force=True, client_name="second")
            assert second.taken_from == first.holder
            assert second.setpoint is not None
            assert second.setpoint["type"] == "velocity_ned"
            with pytest.raises(NoLease) as taken:
                await sky.hold()
            assert taken.value.status == 423
            assert taken.value.holder == second.holder

            await other.set_setpoint(
                PositionNed(north_m=here.north_m, east_m=here.east_m, down_m=-ALTITUDE_M)
            )
            assert (await other.land()).result == "ACCEPTED"
            await other.wait_until(lambda s: not s.armed, timeout_s=120, what="landing")
        finally:
            watcher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await watcher

    assert any(m.state is not None and m.state.armed for m in messages)
    assert {"armed": True} in _events(messages, "armed")
    actions = [event.get("action") for event in _events(messages, "control")]
    assert "acquired" in actions
    assert "taken_over" in actions


async def _pending_request(holder: AsyncSkyHelm) -> str:
    async def request() -> dict[str, str] | None:
        pending: dict[str, str] | None = (await holder.control_status())["request"]
        return pending

    found = await eventually(request, 10.0, "the takeover request")
    assert found is not None
    return found["request_id"]


async def test_a_takeover_is_asked_and_the_holder_answers(served: Served) -> None:
    async with AsyncSkyHelm(pilot_url(served)) as holder, AsyncSkyHelm(pilot_url(served)) as asker:
        first = await holder.acquire(client_name="holder")

        asking = asyncio.create_task(asker.take_over(client_name="asker"))
        request_id = await _pending_request(holder)
        await holder.answer_takeover(request_id, grant=False)
        with pytest.raises(Refused) as denied:
            await asking
        assert denied.value.status == 409
        assert first.holder in denied.value.reason
        assert (await holder.renew()).holder == first.holder  # still the holder's

        asking = asyncio.create_task(asker.take_over(client_name="asker"))
        request_id = await _pending_request(holder)
        await holder.answer_takeover(request_id, grant=True)
        granted = await asking
        assert granted.taken_from == first.holder
        assert (await asker.control_status())["holder"] == granted.holder
        with pytest.raises(NoLease):
            await holder.renew()
        assert holder.lease is None
