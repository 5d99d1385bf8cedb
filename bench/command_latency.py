"""Arm → COMMAND_ACK round trip: SkyHelm's Link/Vehicle vs MAVSDK on one simulated vehicle.

The simulated vehicle runs as its own process (``python -m sim``), as in ``skyhelm serve``.
SkyHelm talks to its API socket, MAVSDK (mavsdk_server) to its GCS socket, so each client
gets its own acknowledgements. Rounds alternate between the clients (arm, then disarm
before the next) so both see the same machine conditions. Figures are the wall time of
``await vehicle.arm()`` and ``await drone.action.arm()``, and SkyHelm's own
``CommandResult.elapsed_ms`` (send to ACK).

Goal: median SkyHelm / median MAVSDK ≤ 1.

    .venv/bin/python -m bench.command_latency [--count 30]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import socket
import statistics
import time
from collections.abc import AsyncIterator, Sequence
from typing import Any

from bench._markdown import table
from bench._report import Section, save_figure
from bench._results import machine_info, write_results
from server.link import Link, Vehicle
from server.simproc import SimInstance, SimProcess

READY_TIMEOUT_S = 30.0


@contextlib.asynccontextmanager
async def simulated_vehicle() -> AsyncIterator[SimInstance]:
    """``python -m sim`` started as ``skyhelm serve`` starts it, on ephemeral ports."""
    sim = SimProcess()
    instances = await sim.start()
    try:
        yield instances[0]
    finally:
        await sim.stop()


async def _until_ready(vehicle: Vehicle) -> None:
    deadline = time.monotonic() + READY_TIMEOUT_S
    while vehicle.snapshot().home is None:
        if time.monotonic() > deadline:
            raise RuntimeError("the vehicle never reported a home position")
        await asyncio.sleep(0.1)


async def _skyhelm_arm_ms(vehicle: Vehicle) -> tuple[float, float]:
    begin = time.perf_counter()
    result = await vehicle.arm()
    wall_ms = (time.perf_counter() - begin) * 1e3
    if not result.ok:
        raise RuntimeError(f"SkyHelm arm refused: {result}")
    disarmed = await vehicle.disarm()
    if not disarmed.ok:
        raise RuntimeError(f"SkyHelm disarm refused: {disarmed}")
    return wall_ms, result.elapsed_ms


async def _mavsdk_arm_ms(drone: Any) -> float:
    begin = time.perf_counter()
    await drone.action.arm()
    wall_ms = (time.perf_counter() - begin) * 1e3
    await drone.action.disarm()
    return wall_ms


def _free_tcp_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _summary(values_ms: Sequence[float]) -> dict[str, float]:
    ordered = sorted(values_ms)
    return {
        "median_ms": statistics.median(ordered),
        "p90_ms": ordered[min(len(ordered) - 1, int(0.9 * len(ordered)))],
        "min_ms": ordered[0],
        "max_ms": ordered[-1],
    }


def _import_mavsdk() -> Any:
    """mavsdk_grpc, without the uvloop event-loop policy its import installs when uvloop is
    there: a policy swapped under a running default loop breaks its child processes (the
    simulated vehicle), and both clients must be measured on the same loop."""
    policy = asyncio.get_event_loop_policy()
    import mavsdk_grpc

    asyncio.set_event_loop_policy(policy)
    return mavsdk_grpc


async def run(count: int) -> dict[str, Any]:
    mavsdk = _import_mavsdk()

    load_average_before = os.getloadavg()
    async with simulated_vehicle() as instance:
        link = await Link.open(instance.url,
                               name="bench-latency")
        drone = mavsdk.System(port=_free_tcp_port())
        try:
            vehicle = await asyncio.wait_for(link.subscribe_vehicles().get(), READY_TIMEOUT_S)
            await _until_ready(vehicle)
            await drone.connect(system_address=f"udpout://127.0.0.1:{instance.gcs_local_port}")
            async for state in drone.core.connection_state():
                if state.is_connected:
                    break
            ours_wall: list[float] = []
            ours_ack: list[float] = []
            theirs: list[float] = []
            for _ in range(count):
                wall_ms, ack_ms = await _skyhelm_arm_ms(vehicle)
                ours_wall.append(wall_ms)
                ours_ack.append(ack_ms)
                theirs.append(await _mavsdk_arm_ms(drone))
        finally:
            with contextlib.suppress(Exception):
                drone._stop_mavsdk_server()
            await link.close()
    ours = _summary(ours_wall)
    mavsdk_summary = _summary(theirs)
    ratio = ours["median_ms"] / mavsdk_summary["median_ms"]
    return {
        "count": count,
        "skyhelm_arm_wall": ours,
        "skyhelm_arm_elapsed_ms": _summary(ours_ack),
        "mavsdk_arm_wall": mavsdk_summary,
        "median_ratio_skyhelm_over_mavsdk": ratio,
        "goal_met": ratio <= 1.0,
        "samples_ms": {"skyhelm": ours_wall, "mavsdk": theirs},
        "machine": machine_info(load_average_before),
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=30, help="arms per client (≥ 30)")
    args = parser.parse_args(argv)
    result = asyncio.run(run(args.count))
    print(f"{'client':10} {'median ms':>10} {'p90 ms':>8} {'min ms':>8} {'max ms':>8}")
    for name, key in (("skyhelm", "skyhelm_arm_wall"), ("mavsdk", "mavsdk_arm_wall")):
        row = result[key]
        print(f"{name:10} {row['median_ms']:10.2f} {row['p90_ms']:8.2f} {row['min_ms']:8.2f} "
              f"{row['max_ms']:8.2f}")
    print(f"SkyHelm send→ACK (CommandResult.elapsed_ms) median "
          f"{result['skyhelm_arm_elapsed_ms']['median_ms']:.2f} ms")
    print(f"median ratio SkyHelm/MAVSDK = {result['median_ratio_skyhelm_over_mavsdk']:.2f} "
          f"(goal ≤ 1: {'met' if result['goal_met'] else 'NOT met'})")
    write_results("command_latency", result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


def report(result: dict[str, Any]) -> Section | None:
    """The round trips of both clients as distributions, and the ratio of their medians."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    ours, theirs = result["skyhelm_arm_wall"], result["mavsdk_arm_wall"]
    samples = result.get("samples_ms", {})
    figures = []
    if samples.get("skyhelm") and samples.get("mavsdk"):
        fig = Figure(figsize=(6.4, 3.4))
        ax = fig.add_subplot()
        for name, values in (("SkyHelm", samples["skyhelm"]), ("MAVSDK", samples["mavsdk"])):
            ordered = sorted(values)
            ax.step(ordered, [(i + 1) / len(ordered) for i in range(len(ordered))],
                    where="post", label=f"{name} (median {statistics.median(ordered):.2f} ms)")
        ax.set_xscale("log")
        ax.set_xlabel("arm → COMMAND_ACK, wall time (ms, log)")
        ax.set_ylabel("fraction of commands")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="lower right")
        figures.append(save_figure(
            fig, "command_latency",
            f"Arm round trip on one simulated vehicle, {result['count']} commands per client, "
            "alternating", result["machine"]))
    rows = [
        ["SkyHelm (`await vehicle.arm()`)", *(f"{ours[k]:.2f}" for k in
                                               ("median_ms", "p90_ms", "max_ms"))],
        ["MAVSDK (`drone.action.arm()`)", *(f"{theirs[k]:.2f}" for k in
                                            ("median_ms", "p90_ms", "max_ms"))],
    ]
    ratio = result["median_ratio_skyhelm_over_mavsdk"]
    markdown = (
        f"SkyHelm's arm round trip takes **{ratio:.2f}×** MAVSDK's (median over "
        f"{result['count']} arms each, alternating on the same simulated vehicle; goal ≤ 1: "
        f"{'met' if ratio <= 1 else 'NOT met'}).\n\n"
        + table(["client", "median ms", "p90 ms", "max ms"], rows)
    )
    return Section("Command round trip: SkyHelm vs MAVSDK", 20, markdown, figures)
