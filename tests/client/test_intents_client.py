"""Intents through the asyncio client: a live velocity braked by the deadman when it is not
renewed, an offset within the envelope and one beyond it, and a brake."""

from __future__ import annotations

import asyncio
import contextlib

import pytest

from skyhelm_client import AsyncSkyHelm, InvalidInput, Message, PositionNed
from tests.client.conftest import pilot_url
from tests.serve_process import Served

ALTITUDE_M = 5.0


async def _deadman_event(sky: AsyncSkyHelm, opened: asyncio.Event) -> Message:
    async with contextlib.aclosing(sky.telemetry(rate_hz=1)) as messages:
        async for message in messages:
            opened.set()
            if message.kind == "deadman":
                return message
    raise AssertionError("the telemetry socket closed")


async def test_velocity_offset_and_brake_intents(served: Served) -> None:
    async with AsyncSkyHelm(pilot_url(served)) as sky:
        await sky.wait_until(lambda s: s.ready_to_fly, timeout_s=30)
        await sky.acquire(client_name="intents")
        await sky.arm()
        await sky.takeoff(altitude_m=ALTITUDE_M)
        here = (
            await sky.wait_until(lambda s: s.altitude_m > ALTITUDE_M - 0.5, timeout_s=60)
        ).position_ned
        await sky.offboard_start(
            PositionNed(north_m=here.north_m, east_m=here.east_m, down_m=-ALTITUDE_M)
        )

        opened = asyncio.Event()
        deadman = asyncio.create_task(_deadman_event(sky, opened))
        await asyncio.wait_for(opened.wait(), 10)
        flying = await sky.velocity(frame="ned", north_m_s=2.0)
        assert flying["intent"] == "velocity"
        assert flying["live"] is True
        braked = await asyncio.wait_for(deadman, 30)  # no further input: the deadman brakes
        assert braked.data["data"]["cause"] == "live_timeout"
        stopped = await sky.wait_until(lambda s: s["ground_speed_m_s"] < 0.3, timeout_s=30)
        assert stopped.mode == "OFFBOARD"
        assert stopped.position_ned.north_m > here.north_m

        moved = await sky.offset(east_m=3.0)
        assert moved["intent"] == "offset"
        assert moved["target"] is not None
        with pytest.raises(InvalidInput) as too_far:
            await sky.offset(north_m=5000.0)
        assert too_far.value.status == 422
        assert too_far.value.field == "north_m"
        assert too_far.value.limit == 500.0

        held = await sky.brake()
        assert held["intent"] == "brake"
        await sky.land()
        await sky.wait_until(lambda s: not s.armed, timeout_s=120, what="landing")
