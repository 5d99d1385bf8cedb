"""CPU cost of the simulated vehicle: share of one core per hovering quad in real time,
and the most quads one process keeps in real time.

For N = 1, 10, 20, 30 quads in one SimCluster (speed 1, both links streaming PX4's default
rates to UDP sinks) it measures the process CPU time over wall time, first with every quad
landed and disarmed (LANDED_S seconds, as the vehicles of bench.many_vehicles are), then
armed and hovering at 2.5 m (--seconds), with the sim-time/wall-time ratio and the
stepping loop's lag behind its 250 Hz deadlines. "Real time" means sim time keeps up with
wall time (ratio ≥ 0.98) and the mean lag stays below one step (4 ms).

    .venv/bin/python -m bench.sim_cost [--seconds 6] [--counts 1,10,20,30] [--quick]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import socket
import time
from typing import TYPE_CHECKING, Any

from bench._results import machine_info, write_results
from sim.lib import modes
from sim.process.runner import SimCluster
from sim.vehicle import PHYSICS_DT_S

if TYPE_CHECKING:
    from bench._report import Section

GOAL_CPU_SHARE_PER_QUAD = 0.03
LANDED_S = 4.0
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
            await sim.wait_ready(60.0)
            cpu0, wall0 = time.process_time(), time.perf_counter()
            await asyncio.sleep(min(LANDED_S, seconds))
            landed_share = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
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
        "landed_cpu_share_of_one_core": round(landed_share, 4),
        "landed_cpu_share_per_quad": round(landed_share / count, 5),
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
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--counts", default="1,10,20,30")
    parser.add_argument("--quick", action="store_true", help="smoke run: 1 and 5 quads, 2 s")
    args = parser.parse_args()
    counts = [1, 5] if args.quick else [int(c) for c in args.counts.split(",")]
    if args.quick:
        args.seconds = 2.0
    load_before = os.getloadavg()
    rows = []
    for count in counts:
        row = asyncio.run(measure(count, args.seconds))
        rows.append(row)
        print(
            f"{count:3d} quads: {100 * row['cpu_share_of_one_core']:6.1f} % of a core, "
            f"{100 * row['cpu_share_per_quad']:5.2f} % per quad (landed "
            f"{100 * row['landed_cpu_share_per_quad']:5.2f} %), sim/wall "
            f"{row['sim_over_wall']:.3f}, loop lag mean {row['loop_mean_lag_ms']:.2f} ms "
            f"max {row['loop_max_lag_ms']:.1f} ms, real time: {row['real_time']}",
            flush=True,
        )
    single = rows[0]["cpu_share_per_quad"] if rows and rows[0]["quads"] == 1 else None
    real_time_counts = [r["quads"] for r in rows if r["real_time"]]
    marginal, fixed = fit_cost([r for r in rows if r["real_time"]])
    result = {
        "machine": machine_info(load_before),
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


def report(result: dict[str, Any]) -> Section | None:
    rows = result.get("rows") or []
    if not rows:
        return None
    from bench._report import Section, pyplot, save_figure

    plt = pyplot()

    n = [r["quads"] for r in rows]
    fig, (total, each) = plt.subplots(1, 2, figsize=(10, 3.8))
    total.plot(n, [100 * r["cpu_share_of_one_core"] for r in rows], "o-", label="hovering")
    landed = [r for r in rows if "landed_cpu_share_of_one_core" in r]
    if landed:
        total.plot([r["quads"] for r in landed],
                   [100 * r["landed_cpu_share_of_one_core"] for r in landed], "s-",
                   label="landed, disarmed")
    total.axhline(100, color="#999", lw=0.8, ls=":", label="one core")
    total.set_xlabel("quads in one process")
    total.set_ylabel("% of one core")
    total.legend(fontsize=7)
    each.bar([str(q) for q in n], [100 * r["cpu_share_per_quad"] for r in rows],
             label="hovering", width=0.4, align="edge")
    if landed:
        each.bar([str(r["quads"]) for r in landed],
                 [100 * r["landed_cpu_share_per_quad"] for r in landed],
                 label="landed, disarmed", width=-0.4, align="edge")
    each.axhline(100 * GOAL_CPU_SHARE_PER_QUAD, color="#c33", lw=0.8, ls=":", label="goal")
    each.set_xlabel("quads in one process")
    each.set_ylabel("% of one core per quad")
    each.legend(fontsize=7)
    fig.tight_layout()
    figure = save_figure(fig, "sim_cost", "Simulated quad CPU cost per vehicle",
                         result["machine"])
    plt.close(fig)
    marginal = result.get("cpu_share_per_additional_quad")
    lines = [
        f"One sim process keeps {result['max_real_time_quads_measured']} hovering quads in real "
        "time (largest N measured).",
    ]
    if marginal:
        lines.append(
            f"Each additional hovering quad costs {100 * marginal:.2f} % of one core "
            f"({marginal / GOAL_CPU_SHARE_PER_QUAD:.2f}× the 3 % goal), streaming PX4's "
            "default rates on both links."
        )
    if landed:
        last = landed[-1]
        ratio = last["cpu_share_per_quad"] / max(last["landed_cpu_share_per_quad"], 1e-9)
        lines.append(
            f"At {last['quads']} quads a hovering quad costs {ratio:.1f}× a landed, disarmed one "
            f"({100 * last['landed_cpu_share_per_quad']:.2f} % of a core)."
        )
    return Section(title="Simulated vehicle cost", order=50, markdown="\n".join(lines),
                   figures=[figure])


if __name__ == "__main__":
    raise SystemExit(main())
