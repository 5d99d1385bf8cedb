"""The stepping loop: every vehicle stepped on absolute sim-time deadlines (t0 + k·dt),
paced by an injected wall clock, optionally faster than real time."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Protocol

from sim.models.sim_run import PHYSICS_DT_S
from sim.process.clock import Clock, EventLoopClock

# The loop runs STEPS_PER_WAKE steps (20 ms of sim time) per wake-up, and wakes no more
# often than MIN_WAKE_PERIOD_S of wall time when faster than real time. Waking alone
# costs this machine ~2 % of a core at 125 Hz and ~0.8 % at 50 Hz, and a batch runs on
# warmer caches; nothing outside can tell: every message keeps its own sim timestamp and
# every stream its rate, the 100 Hz ATTITUDE reaching UDP peers in pairs.
STEPS_PER_WAKE = 5
MIN_WAKE_PERIOD_S = 0.008
# A fast-forward's default speed: PX4's timeouts run on sim time, and a ground station's
# 1 Hz heartbeat still arrives every 8 sim-seconds, within PX4's 10 s data-link timeout.
FAST_FORWARD_SPEED = 8.0


@dataclass
class LoopStats:
    """How late the stepping loop wakes up against its intended times (wall clock)."""

    steps: int = 0
    wakeups: int = 0
    # wall time by which wake-ups came after their intended times: the worst and the sum
    max_lag_s: float = 0.0
    lag_sum_s: float = 0.0

    @property
    def mean_lag_s(self) -> float:
        return self.lag_sum_s / self.wakeups if self.wakeups else 0.0

    def reset(self) -> None:
        for counter in fields(self):
            setattr(self, counter.name, counter.default)


class Steppable(Protocol):
    def step(self, dt_s: float = PHYSICS_DT_S) -> None: ...


class Pace:
    """Sim seconds per wall second, which may change while the loop runs: a test flies the
    set-up of what it times (a take-off, a landing) fast-forward, then the rest at its own
    speed. The loop takes a new speed at its next wake-up and paces from there."""

    speed: float

    def __init__(self, speed: float) -> None:
        self.set(speed)

    def set(self, speed: float) -> None:
        if not speed > 0 or math.isinf(speed):
            raise ValueError(f"speed must be positive and finite, not {speed}")
        self.speed = speed


async def run_vehicles(
    vehicles: Sequence[Steppable],
    speed: float | Pace = 1.0,
    stats: LoopStats | None = None,
    dt_s: float = PHYSICS_DT_S,
    max_catch_up_steps: int = 50,
    clock: Clock | None = None,
) -> None:
    """Step every vehicle at 1/dt_s sim-Hz, sim time running `speed` times wall time (a
    Pace: whatever it says at each wake-up).

    Deadlines are absolute (t0 + k·dt/speed) so timer jitter does not accumulate; it wakes
    every STEPS_PER_WAKE steps (at least MIN_WAKE_PERIOD_S apart) and runs the steps due.
    After a stall it catches up at most `max_catch_up_steps` steps (or four wake-ups'
    worth, if more) at once and then drops the remainder, so sim time slows down rather
    than jumping. A new speed starts new deadlines from the wake-up that sees it.
    """
    clock = clock if clock is not None else EventLoopClock()
    stats = stats if stats is not None else LoopStats()
    pace = speed if isinstance(speed, Pace) else Pace(speed)
    paced = pace.speed
    wall_dt, wake_period_s, catch_up_limit = _pacing(dt_s, paced, max_catch_up_steps)
    t0 = clock.now_s()
    k = 0
    intended_wake = t0
    while True:
        now = clock.now_s()
        if pace.speed != paced:
            paced = pace.speed
            wall_dt, wake_period_s, catch_up_limit = _pacing(dt_s, paced, max_catch_up_steps)
            t0, k = now, 0
        due = int((now - t0) / wall_dt)
        lag = now - intended_wake
        stats.wakeups += 1
        if lag > 0:
            stats.lag_sum_s += lag
            stats.max_lag_s = max(stats.max_lag_s, lag)
        todo = due - k
        if todo > catch_up_limit:
            t0 += (todo - catch_up_limit) * wall_dt
            todo = catch_up_limit
        for _ in range(todo):
            for vehicle in vehicles:
                vehicle.step(dt_s)
        k += max(todo, 0)
        stats.steps += max(todo, 0)
        intended_wake = max(t0 + (k + 1) * wall_dt, now + wake_period_s)
        await clock.sleep_until(intended_wake)


def _pacing(dt_s: float, speed: float, max_catch_up_steps: int) -> tuple[float, float, int]:
    """The wall time of a step, between wake-ups, and the most steps caught up at once."""
    wall_dt = dt_s / speed
    wake_period_s = max(STEPS_PER_WAKE * wall_dt, MIN_WAKE_PERIOD_S)
    # never less than a few wake-ups' worth, or a fast sim could never catch up at all
    return wall_dt, wake_period_s, max(max_catch_up_steps, 4 * math.ceil(wake_period_s / wall_dt))
