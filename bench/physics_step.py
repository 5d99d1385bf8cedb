"""Cost of one 250 Hz physics step (control + mixer + dynamics) per airframe.

Each airframe flies a representative manoeuvre in simulated time; the figure is the median
over several timed blocks of the CPU time of this process per `model.step()` (CPU rather
than wall time, so that other work on a shared machine does not count), with the share of
one core that one vehicle in real time costs and how many such vehicles one core could step
(physics only; the MAVLink side comes on top, see bench/sim_cost.py). Wall time is printed
alongside for reference.
"""

from __future__ import annotations

import statistics
import time

from bench._results import machine_info, write_results
from sim.airframes import AirframeModel, default_params, make_airframe
from sim.sim_run import PHYSICS_DT_S, fly
from sim.topics import TrajectorySetpoint

BLOCKS = 7
STEPS_PER_BLOCK = 2500  # 10 s of simulated flight


def _airborne(name: str) -> tuple[AirframeModel, list[TrajectorySetpoint]]:
    """A model in flight and the setpoints it cycles through while timed."""
    model = make_airframe(name, default_params(name))
    model.reset([0.0, 0.0, 0.0], 0.0)
    if name in ("plane", "vtol"):
        circle = [TrajectorySetpoint(position_ned_m=[0.0, 0.0, -30.0])]
        if name == "plane":
            model.reset([0.0, 0.0, -30.0], 0.0)
            model.truth.velocity_ned_m_s[0] = 15.0
        else:
            fly(model, circle[0], 12.0)
            model.request_transition(to_fixed_wing=True, immediate=False)
        fly(model, circle[0], 10.0)
        return model, circle
    if name == "rover":
        return model, [
            TrajectorySetpoint(position_ned_m=[20.0, 0.0, 0.0]),
            TrajectorySetpoint(position_ned_m=[0.0, 10.0, 0.0]),
        ]
    fly(model, TrajectorySetpoint(position_ned_m=[0.0, 0.0, -10.0]), 6.0)
    return model, [
        TrajectorySetpoint(position_ned_m=[5.8, 0.0, -10.0]),
        TrajectorySetpoint(velocity_ned_m_s=[0.0, 2.0, 0.0], yawspeed_rad_s=0.3),
        TrajectorySetpoint(position_ned_m=[0.0, 0.0, -10.0], yaw_rad=1.0),
    ]


def measure(name: str) -> dict[str, float]:
    model, setpoints = _airborne(name)
    per_step_us: list[float] = []
    wall_us: list[float] = []
    for block in range(BLOCKS):
        sp = setpoints[block % len(setpoints)]
        cpu_start, wall_start = time.process_time(), time.perf_counter()
        for _ in range(STEPS_PER_BLOCK):
            model.step(PHYSICS_DT_S, True, sp)
        per_step_us.append((time.process_time() - cpu_start) / STEPS_PER_BLOCK * 1e6)
        wall_us.append((time.perf_counter() - wall_start) / STEPS_PER_BLOCK * 1e6)
    median = statistics.median(per_step_us)
    core_share = median * 1e-6 / PHYSICS_DT_S
    return {
        "step_us_median": round(median, 2),
        "step_us_min": round(min(per_step_us), 2),
        "step_us_max": round(max(per_step_us), 2),
        "wall_step_us_median": round(statistics.median(wall_us), 2),
        "core_percent_at_250_hz": round(100.0 * core_share, 3),
        "vehicles_per_core_physics_only": int(1.0 / core_share),
    }


def main() -> None:
    results = {name: measure(name) for name in ("quad", "hexa", "octo", "plane", "vtol", "rover")}
    print(
        f"{'airframe':8} {'CPU µs/step':>11} {'min':>7} {'max':>7} {'wall µs':>8}"
        f" {'% core':>7} {'per core':>9}"
    )
    for name, r in results.items():
        print(
            f"{name:8} {r['step_us_median']:11.1f} {r['step_us_min']:7.1f}"
            f" {r['step_us_max']:7.1f} {r['wall_step_us_median']:8.1f}"
            f" {r['core_percent_at_250_hz']:7.2f} {r['vehicles_per_core_physics_only']:9d}"
        )
    write_results(
        "physics_step",
        {
            "benchmark": "physics_step",
            "physics_rate_hz": round(1.0 / PHYSICS_DT_S),
            "machine": machine_info(),
            "airframes": results,
        },
    )


if __name__ == "__main__":
    main()
