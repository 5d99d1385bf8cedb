"""CPU cost of the simulated vehicle: share of one core per hovering quad in real time,
and the most quads one process keeps in real time.

For N = 1, 5, 10, 20, 30 quads in one SimCluster (speed 1, both links streaming to UDP
sinks, every quad armed and hovering at 2.5 m) it measures the process CPU time over
wall time for MEASURE_S seconds, the sim-time/wall-time ratio and the stepping loop's
lag behind its 250 Hz deadlines. "Real time" means sim time keeps up with wall time
(ratio ≥ 0.98) and the mean lag stays below one step (4 ms).

    .venv/bin/python -m bench.sim_cost [--seconds 10] [--counts 1,5,10,20,30]
"""

from __future__ import annotations

import argparse
import asyncio
import socket
import time
from typing import Any

from bench._results import machine_info, write_results
from sim import modes
from sim.runner import SimCluster
from sim.vehicle import PHYSICS_DT_S

GOAL_CPU_SHARE_PER_QUAD = 0.03
GOAL_VEHICLES = 20
REAL_TIME_RATIO = 0.98


def bind_sinks(count: int) -> tuple[int, list[socket.socket]]:
    """count consecutive UDP ports (instance i sends to base + i), never read."""
    for _ in range(50):
        probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        probe.bind(("127.0.0.1", 0))
        base = probe.getsockname()[1]
        sinks = [probe]
        try:
            for i in range(1, count):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                sinks.append(s)
                s.bind(("127.0.0.1", base + i))
            return base, sinks
        except OSError:
            for s in sinks:
                s.close()
    raise RuntimeError("no run of free consecutive UDP ports")


async def hover_all(sim: SimCluster, timeout_s: float) -> None:
    await sim.wait_ready(timeout_s)
    for inst in sim.instances:
        inst.vehicle.commander.request_mode(modes.AUTO_TAKEOFF)
        inst.vehicle.commander.arm(inst.vehicle.now_s)
    deadline = time.monotonic() + timeout_s
    while any(i.vehicle.mode_name != "AUTO_LOITER" for i in sim.instances):
        if time.monotonic() > deadline:
            raise RuntimeError("quads did not reach Hold")
        await asyncio.sleep(0.1)


async def measure(count: int, seconds: float) -> dict[str, Any]:
    api_base, api_sinks = bind_sinks(count)
    gcs_base, gcs_sinks = bind_sinks(1)
    try:
        async with SimCluster(count=count, api_port=api_base, gcs_port=gcs_base) as sim:
            await hover_all(sim, timeout_s=60.0)
            stats = sim.loop_stats
            stats.reset()
            vehicle = sim.instances[0].vehicle
            sim0, wall0, cpu0 = vehicle.now_s, time.perf_counter(), time.process_time()
            await asyncio.sleep(seconds)
            sim1, wall1, cpu1 = vehicle.now_s, time.perf_counter(), time.process_time()
    finally:
        for s in api_sinks + gcs_sinks:
            s.close()
    wall = wall1 - wall0
    cpu_share = (cpu1 - cpu0) / wall
    ratio = (sim1 - sim0) / wall
    mean_lag_s = stats.mean_lag_s
    return {
        "quads": count,
        "wall_s": round(wall, 2),
        "cpu_share_of_one_core": round(cpu_share, 4),
        "cpu_share_per_quad": round(cpu_share / count, 5),
        "sim_over_wall": round(ratio, 4),
        "loop_mean_lag_ms": round(mean_lag_s * 1000, 3),
        "loop_max_lag_ms": round(stats.max_lag_s * 1000, 2),
        "real_time": ratio >= REAL_TIME_RATIO and mean_lag_s < PHYSICS_DT_S,
    }


def fit_cost(rows: list[dict[str, Any]]) -> tuple[float | None, float]:
    """Least-squares line through CPU share over quad count: (per quad, fixed part)."""
    if len(rows) < 2:
        return None, 0.0
    xs = [float(r["quads"]) for r in rows]
    ys = [float(r["cpu_share_of_one_core"]) for r in rows]
    mean_x, mean_y = sum(xs) / len(xs), sum(ys) / len(ys)
    slope = sum((x - mean_x) * (y - mean_y) for x, y in zip(xs, ys, strict=True)) / sum(
        (x - mean_x) ** 2 for x in xs
    )
    return round(slope, 5), round(mean_y - slope * mean_x, 4)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--counts", default="1,5,10,20,30")
    args = parser.parse_args()
    counts = [int(c) for c in args.counts.split(",")]
    rows = []
    for count in counts:
        row = asyncio.run(measure(count, args.seconds))
        rows.append(row)
        print(
            f"{count:3d} quads: {100 * row['cpu_share_of_one_core']:6.1f} % of a core, "
            f"{100 * row['cpu_share_per_quad']:5.2f} % per quad, sim/wall "
            f"{row['sim_over_wall']:.3f}, loop lag mean {row['loop_mean_lag_ms']:.2f} ms "
            f"max {row['loop_max_lag_ms']:.1f} ms, real time: {row['real_time']}",
            flush=True,
        )
    single = rows[0]["cpu_share_per_quad"] if rows and rows[0]["quads"] == 1 else None
    real_time_counts = [r["quads"] for r in rows if r["real_time"]]
    marginal, fixed = fit_cost([r for r in rows if r["real_time"]])
    result = {
        "machine": machine_info(),
        "seconds_per_point": args.seconds,
        "rows": rows,
        "cpu_share_per_quad_single": single,
        "max_real_time_quads_measured": max(real_time_counts, default=0),
        "cpu_share_per_additional_quad": marginal,
        "cpu_share_fixed_overhead": fixed,
        "goal_cpu_share_per_quad": GOAL_CPU_SHARE_PER_QUAD,
        "goal_vehicles": GOAL_VEHICLES,
    }
    write_results("sim_cost", result)
    print(f"per quad (N=1): {100 * single:.2f} % of one core (goal ≤ 3 %)" if single else "")
    if marginal is not None:
        print(f"each additional quad: {100 * marginal:.2f} % of one core "
              f"(fixed overhead of the process and its event loop {100 * fixed:.1f} %)")
    print(f"largest N in real time: {result['max_real_time_quads_measured']} (goal ≥ 20)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
