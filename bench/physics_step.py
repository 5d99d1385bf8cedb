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
from typing import Any

from bench._markdown import table
from bench._report import Section, save_figure
from bench._results import machine_info, write_results
from sim.lib.topics import TrajectorySetpoint
from sim.models.airframes import AirframeModel, default_params, make_airframe
from sim.models.sim_run import PHYSICS_DT_S, fly

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


def report(result: dict[str, Any]) -> Section | None:
    """CPU per step per airframe, as a share of the step's real-time budget."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    airframes = result["airframes"]
    rate_hz = result["physics_rate_hz"]
    budget_us = 1e6 / rate_hz
    names = list(airframes)
    fig = Figure(figsize=(6.4, 3.0))
    ax = fig.add_subplot()
    medians = [airframes[n]["step_us_median"] for n in names]
    bars = ax.bar(names, medians, color="#4c72b0")
    ax.errorbar(names, medians, yerr=[[m - airframes[n]["step_us_min"] for n, m in
                                       zip(names, medians, strict=True)],
                                      [airframes[n]["step_us_max"] - m for n, m in
                                       zip(names, medians, strict=True)]],
                fmt="none", ecolor="#333333", capsize=3)
    ax.bar_label(bars, labels=[f"{100 * m / budget_us:.1f} %" for m in medians], padding=2,
                 fontsize=8)
    ax.set_ylabel(f"CPU µs per step (labels: share of {budget_us:.0f} µs)")
    ax.set_ylim(0, max(airframes[n]["step_us_max"] for n in names) * 1.25)
    figure = save_figure(fig, "physics_step",
                         f"CPU per {rate_hz} Hz physics step, median of blocks (bars: min–max)",
                         result["machine"])
    quad = airframes.get("quad")
    rows = [[n, f"{a['step_us_median']:.1f}", f"{a['core_percent_at_250_hz']:.2f}",
             a["vehicles_per_core_physics_only"]] for n, a in airframes.items()]
    lead = (f"A quad's physics step costs {quad['step_us_median'] / budget_us:.3f}× its "
            f"{budget_us:.0f} µs real-time budget: one core could step "
            f"{quad['vehicles_per_core_physics_only']} quads (physics only; see the sim cost "
            f"for MAVLink on top).\n\n") if quad else ""
    return Section("Physics step per airframe", 60, lead + table(
        ["airframe", "CPU µs/step", "% of a core at 250 Hz", "vehicles per core"], rows),
        [figure])
