"""The stepping loop: absolute sim-time deadlines, steps batched per wake-up, catch-up.

It runs on a ManualClock, so wall time is whatever the test says it is: pacing is checked
exactly and no test waits for real time to pass.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable

import pytest

from sim.models.sim_run import PHYSICS_DT_S
from sim.process.clock import ManualClock
from sim.process.run_loop import (
    MIN_WAKE_PERIOD_S,
    STEPS_PER_WAKE,
    LoopStats,
    Pace,
    run_vehicles,
)


class CountingVehicle:
    def __init__(self) -> None:
        self.now_s = 0.0
        self.steps = 0

    def step(self, dt_s: float = PHYSICS_DT_S) -> None:
        self.now_s += dt_s
        self.steps += 1


class Loop:
    """run_vehicles on a ManualClock with one CountingVehicle."""

    def __init__(self, speed: float | Pace, max_catch_up_steps: int) -> None:
        self.clock = ManualClock()
        self.vehicle = CountingVehicle()
        self.stats = LoopStats()
        self.task = asyncio.create_task(run_vehicles(
            [self.vehicle], speed, self.stats, max_catch_up_steps=max_catch_up_steps,
            clock=self.clock))


LoopStarter = Callable[..., Awaitable[Loop]]


@pytest.fixture
async def start_loop() -> AsyncIterator[LoopStarter]:
    loops: list[Loop] = []

    async def start(speed: float | Pace, max_catch_up_steps: int = 50) -> Loop:
        loop = Loop(speed, max_catch_up_steps)
        loops.append(loop)
        await loop.clock.advance(0.0)  # the task takes its start time
        return loop

    yield start
    for loop in loops:
        loop.task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await loop.task


async def test_real_time_runs_several_steps_per_wake_up_and_keeps_up(
    start_loop: LoopStarter,
) -> None:
    loop = await start_loop(1.0)
    await loop.clock.advance(0.6)
    # the steps due by the last wake-up have run, and none ahead of time
    due = round(0.6 / PHYSICS_DT_S)
    assert due - STEPS_PER_WAKE <= loop.vehicle.steps <= due
    assert loop.stats.steps / loop.stats.wakeups >= STEPS_PER_WAKE - 1
    assert loop.stats.max_lag_s == 0.0


async def test_much_faster_than_real_time_still_keeps_its_speed(start_loop: LoopStarter) -> None:
    # 100x: 200 steps are due per 8 ms wake-up, more than the default catch-up limit of 50
    speed = 100.0
    loop = await start_loop(speed)
    await loop.clock.advance(0.5)
    assert loop.vehicle.now_s == pytest.approx(speed * 0.5, abs=speed * MIN_WAKE_PERIOD_S)
    # wake-ups are MIN_WAKE_PERIOD_S apart however many steps each one runs
    assert loop.stats.wakeups <= 0.5 / MIN_WAKE_PERIOD_S + 2


async def test_a_new_speed_is_kept_from_the_next_wake_up_without_a_jump(
    start_loop: LoopStarter,
) -> None:
    pace = Pace(1.0)
    loop = await start_loop(pace)
    await loop.clock.advance(1.0)
    at_1x = loop.vehicle.now_s
    assert at_1x == pytest.approx(1.0, abs=STEPS_PER_WAKE * PHYSICS_DT_S)

    pace.set(8.0)  # fast-forward: 8 s of sim time in each wall second from here
    await loop.clock.advance(1.0)
    fast = loop.vehicle.now_s - at_1x
    # less at most the wake-up still due at 1x when it was set, and the last one not yet due
    wake_1x_s = STEPS_PER_WAKE * PHYSICS_DT_S
    assert 8.0 - 7.0 * wake_1x_s - 8.0 * MIN_WAKE_PERIOD_S <= fast <= 8.0
    # kept pace at 8x: no step dropped as if it had stalled, none run ahead
    assert loop.stats.max_lag_s <= MIN_WAKE_PERIOD_S

    pace.set(1.0)  # and back: the time it ran fast is not paid back by running slow
    await loop.clock.advance(1.0)
    assert loop.vehicle.now_s - at_1x - fast == pytest.approx(1.0, abs=2 * wake_1x_s)


@pytest.mark.parametrize("speed", [0.0, -1.0, float("nan"), float("inf")])
def test_a_pace_is_positive_and_finite(speed: float) -> None:
    with pytest.raises(ValueError, match="speed"):
        Pace(speed)
    pace = Pace(2.0)
    with pytest.raises(ValueError, match="speed"):
        pace.set(speed)
    assert pace.speed == 2.0


async def test_after_a_stall_catches_up_a_bounded_number_of_steps_then_slows_down(
    start_loop: LoopStarter,
) -> None:
    loop = await start_loop(1.0, max_catch_up_steps=50)
    await loop.clock.advance(0.1)
    before = loop.vehicle.steps
    loop.clock.stall(2.0)  # 500 steps' worth of wall time with nobody woken
    await loop.clock.advance(0.0)
    assert loop.vehicle.steps - before == 50
    # woken late by the stall, less the part of a wake period that was still to come
    assert 2.0 - STEPS_PER_WAKE * PHYSICS_DT_S <= loop.stats.max_lag_s <= 2.0
    # from then on it keeps pace again, the dropped steps never made up
    await loop.clock.advance(1.0)
    resumed = loop.vehicle.steps - before - 50
    assert round(1.0 / PHYSICS_DT_S) - STEPS_PER_WAKE <= resumed <= round(1.0 / PHYSICS_DT_S)


@pytest.mark.looptime
async def test_on_the_event_loop_clock_virtual_time_paces_it_exactly() -> None:
    # the default clock is the event loop's: under looptime ten seconds pass at once
    vehicle, stats = CountingVehicle(), LoopStats()
    task = asyncio.create_task(run_vehicles([vehicle], 2.0, stats))
    await asyncio.sleep(10.0)
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
    due = round(2.0 * 10.0 / PHYSICS_DT_S)
    assert due - STEPS_PER_WAKE <= vehicle.steps <= due
    assert stats.max_lag_s == pytest.approx(0.0, abs=1e-9)
