"""Running an airframe model in simulated time, without sockets or a wall clock.

The MAVLink side drives models at 250 Hz from its own loop; benches and tests use this to
fly a model directly, much faster than real time.
"""

from __future__ import annotations

from collections.abc import Callable

from sim.lib.topics import ControlSetpoint
from sim.models.airframes import AirframeModel

PHYSICS_DT_S = 0.004  # 250 Hz, PX4 SIH's rate


def fly(
    model: AirframeModel,
    setpoint: ControlSetpoint | None,
    duration_s: float,
    until: Callable[[], bool] | None = None,
    armed: bool = True,
    dt_s: float = PHYSICS_DT_S,
) -> float | None:
    """Step the model for up to duration_s; the simulated time at which `until` first held,
    or None if it never did (or no condition was given)."""
    steps = round(duration_s / dt_s)
    for i in range(steps):
        model.step(dt_s, armed, setpoint)
        if until is not None and until():
            return (i + 1) * dt_s
    return None


def fly_peak(
    model: AirframeModel,
    setpoint: ControlSetpoint | None,
    duration_s: float,
    measure: Callable[[], float],
    armed: bool = True,
    dt_s: float = PHYSICS_DT_S,
) -> float:
    """Step the model for duration_s; the largest value `measure` took after any step."""
    peak = -float("inf")
    for _ in range(round(duration_s / dt_s)):
        model.step(dt_s, armed, setpoint)
        peak = max(peak, measure())
    return peak
