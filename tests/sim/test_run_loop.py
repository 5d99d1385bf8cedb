"""The stepping loop: absolute sim-time deadlines, steps batched per wake-up, catch-up."""

from __future__ import annotations

import asyncio
import contextlib
import time

from sim.vehicle import PHYSICS_DT_S, STEPS_PER_WAKE, LoopStats, run_vehicles


class CountingVehicle:
    def __init__(self) -> None:
        self.now_s = 0.0

    def step(self, dt_s: float = PHYSICS_DT_S) -> None:
        self.now_s += dt_s


async def run_for(speed: float, wall_s: float) -> tuple[CountingVehicle, LoopStats, float]:
    vehicle, stats = CountingVehicle(), LoopStats()
    task = asyncio.create_task(run_vehicles([vehicle], speed, stats))
    start = time.perf_counter()
    await asyncio.sleep(wall_s)
    elapsed = time.perf_counter() - start
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
    return vehicle, stats, elapsed


async def test_real_time_runs_several_steps_per_wake_up_and_keeps_up() -> None:
    vehicle, stats, elapsed = await run_for(1.0, 0.6)
    assert vehicle.now_s >= 0.8 * elapsed
    assert vehicle.now_s <= elapsed + 2 * STEPS_PER_WAKE * PHYSICS_DT_S
    assert stats.steps / stats.wakeups >= STEPS_PER_WAKE - 1


async def test_much_faster_than_real_time_still_keeps_its_speed() -> None:
    # 100x: 200 steps are due per 8 ms wake-up, more than the default catch-up limit of 50
    speed = 100.0
    vehicle, _, elapsed = await run_for(speed, 0.5)
    assert vehicle.now_s >= 0.7 * speed * elapsed
