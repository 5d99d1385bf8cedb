"""Setpoint stream regularity: SkyHelm's streamer under event-loop load vs MAVSDK's.

A stand-in vehicle in another process (bench/_receiver.py) timestamps every
SET_POSITION_TARGET_LOCAL_NED as it arrives. SkyHelm streams a position setpoint at 20, 50
and 100 Hz from an event loop that is also busy JSON-encoding vehicle snapshots every few
milliseconds (what the WebSocket API does for its clients); then MAVSDK (mavsdk_server)
streams its offboard setpoint at its fixed 20 Hz to the same receiver, with the same load
still running on this machine.

Goal: SkyHelm's p99 |interval − period| at 50 Hz ≤ MAVSDK's at 20 Hz; no gap > 100 ms.

    .venv/bin/python -m bench.stream_jitter [--seconds 30]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import dataclasses
import itertools
import json
import os
import socket
import statistics
import sys
import time
from collections.abc import AsyncIterator, Sequence
from pathlib import Path
from typing import Any

from bench._results import machine_info, write_results
from server.link import Envelope, Link, PositionNed, Vehicle

PROJECT_ROOT = Path(__file__).resolve().parent.parent
SKYHELM_RATES_HZ = (20.0, 50.0, 100.0)
MAVSDK_RATE_HZ = 20.0  # MAVSDK's OffboardImpl SEND_INTERVAL_S = 0.05, not configurable
GAP_LIMIT_S = 0.100
# Event-loop load: every LOAD_PERIOD_S, JSON-encode the snapshot LOAD_ENCODES times
# (500 encodes/s: a 50 Hz telemetry feed to ten WebSocket clients, each encoded apart).
LOAD_PERIOD_S = 0.004
LOAD_ENCODES = 2


class ReceiverProcess:
    """bench/_receiver.py as a child process, driven over its stdin/stdout."""

    def __init__(self, proc: asyncio.subprocess.Process, port: int) -> None:
        self.proc = proc
        self.port = port

    @classmethod
    @contextlib.asynccontextmanager
    async def running(cls) -> AsyncIterator[ReceiverProcess]:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "bench._receiver",
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
            cwd=PROJECT_ROOT,
        )
        try:
            ready = json.loads(await cls._line(proc))
            yield cls(proc, int(ready["port"]))
        finally:
            if proc.returncode is None:
                assert proc.stdin is not None
                proc.stdin.write(b"quit\n")
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(proc.wait(), 5.0)
            if proc.returncode is None:
                proc.kill()
                await proc.wait()

    @staticmethod
    async def _line(proc: asyncio.subprocess.Process) -> bytes:
        assert proc.stdout is not None
        return await asyncio.wait_for(proc.stdout.readline(), 30.0)

    async def reset(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(b"reset\n")
        await self.proc.stdin.drain()

    async def arrivals(self) -> dict[str, list[float]]:
        assert self.proc.stdin is not None
        self.proc.stdin.write(b"report\n")
        await self.proc.stdin.drain()
        report: dict[str, dict[str, list[float]]] = json.loads(await self._line(self.proc))
        return report["arrivals"]


def interval_figures(arrivals: Sequence[float], rate_hz: float) -> dict[str, Any]:
    period_s = 1.0 / rate_hz
    intervals = [b - a for a, b in itertools.pairwise(arrivals)]
    if not intervals:
        return {"rate_hz": rate_hz, "received": len(arrivals)}
    errors = sorted(abs(i - period_s) for i in intervals)
    ordered = sorted(intervals)
    return {
        "rate_hz": rate_hz,
        "received": len(arrivals),
        "measured_rate_hz": len(intervals) / (arrivals[-1] - arrivals[0]),
        "interval_p50_ms": _percentile(ordered, 0.50) * 1e3,
        "interval_p99_ms": _percentile(ordered, 0.99) * 1e3,
        "interval_max_ms": ordered[-1] * 1e3,
        "abs_error_p99_ms": _percentile(errors, 0.99) * 1e3,
        "abs_error_mean_ms": statistics.fmean(errors) * 1e3,
        "gaps_over_100ms": sum(i > GAP_LIMIT_S for i in intervals),
    }


def _percentile(ordered: Sequence[float], q: float) -> float:
    """Nearest-rank percentile of an ascending sequence."""
    return ordered[max(0, min(len(ordered) - 1, int(q * len(ordered) + 0.999999) - 1))]


class LoopLoad:
    """Keeps the event loop busy the way snapshot fan-out does, and measures its share."""

    def __init__(self, vehicle: Vehicle, period_s: float, encodes: int) -> None:
        self._vehicle = vehicle
        self.period_s = period_s
        self.encodes = encodes
        self.busy_s = 0.0
        self.started_s = time.perf_counter()

    async def run(self) -> None:
        while True:
            begin = time.perf_counter()
            for _ in range(self.encodes):
                json.dumps(dataclasses.asdict(self._vehicle.snapshot()))
            self.busy_s += time.perf_counter() - begin
            await asyncio.sleep(self.period_s)

    @property
    def busy_fraction(self) -> float:
        return self.busy_s / max(1e-9, time.perf_counter() - self.started_s)


async def measure_skyhelm(
    vehicle: Vehicle, receiver: ReceiverProcess, seconds: float
) -> list[dict[str, Any]]:
    vehicle.envelope = Envelope(None, None, None, None)
    key = f"{vehicle.link.mav.srcSystem}/{vehicle.link.mav.srcComponent}"
    results = []
    setpoint = PositionNed(0.0, 0.0, -5.0, yaw_deg=0.0)
    started = await vehicle.start_offboard(setpoint)
    if not started.ok:
        raise RuntimeError(f"offboard refused by the stand-in vehicle: {started}")
    for rate_hz in SKYHELM_RATES_HZ:
        vehicle.stream_rate_hz = rate_hz
        await vehicle.set_setpoint(setpoint)
        await asyncio.sleep(0.5)  # settle on the new rate before measuring
        await receiver.reset()
        await asyncio.sleep(seconds)
        arrivals = (await receiver.arrivals()).get(key, [])
        figures = interval_figures(arrivals, rate_hz)
        figures["streamer_self_report"] = dataclasses.asdict(vehicle.stream_stats())
        results.append({"client": "skyhelm", **figures})
    return results


async def measure_mavsdk(receiver: ReceiverProcess, seconds: float) -> dict[str, Any]:
    import mavsdk_grpc as mavsdk
    from mavsdk_grpc.offboard import PositionNedYaw

    drone = mavsdk.System(port=_free_tcp_port())
    await drone.connect(system_address=f"udpout://127.0.0.1:{receiver.port}")
    try:
        async for state in drone.core.connection_state():
            if state.is_connected:
                break
        await drone.offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -5.0, 0.0))
        await drone.offboard.start()  # MAVSDK stops streaming to a vehicle not in OFFBOARD
        await asyncio.sleep(0.5)
        await receiver.reset()
        await asyncio.sleep(seconds)
        arrivals = await receiver.arrivals()
        key = f"{drone._sysid}/{drone._compid}"
        return {"client": "mavsdk", **interval_figures(arrivals.get(key, []), MAVSDK_RATE_HZ)}
    finally:
        with contextlib.suppress(Exception):
            drone._stop_mavsdk_server()


def _free_tcp_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def print_table(rows: Sequence[dict[str, Any]]) -> None:
    header = (f"{'client':8} {'Hz':>5} {'recv':>6} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8} "
              f"{'p99|err| ms':>12} {'gaps>100ms':>11}")
    print(header)
    print("-" * len(header))
    for r in rows:
        print(f"{r['client']:8} {r['rate_hz']:5.0f} {r['received']:6d} "
              f"{r.get('interval_p50_ms', float('nan')):8.2f} "
              f"{r.get('interval_p99_ms', float('nan')):8.2f} "
              f"{r.get('interval_max_ms', float('nan')):8.2f} "
              f"{r.get('abs_error_p99_ms', float('nan')):12.2f} "
              f"{r.get('gaps_over_100ms', 0):11d}")


async def run(seconds: float, load_period_s: float, load_encodes: int) -> dict[str, Any]:
    load_average_before = os.getloadavg()
    async with ReceiverProcess.running() as receiver:
        link = await Link.open(f"udpout:127.0.0.1:{receiver.port}", name="bench-jitter")
        try:
            vehicle = await asyncio.wait_for(link.subscribe_vehicles().get(), 10.0)
            load = LoopLoad(vehicle, load_period_s, load_encodes)
            load_task = asyncio.create_task(load.run())
            ours = await measure_skyhelm(vehicle, receiver, seconds)
        finally:
            await link.close()  # stops our stream; the load keeps running for MAVSDK's turn
        try:
            theirs = await measure_mavsdk(receiver, seconds)
        finally:
            load_task.cancel()
    ours_50 = next(r for r in ours if r["rate_hz"] == 50.0)
    goal_jitter = ours_50.get("abs_error_p99_ms", float("inf")) <= theirs.get(
        "abs_error_p99_ms", float("-inf"))
    goal_gaps = all(r.get("gaps_over_100ms", 1) == 0 for r in ours)
    return {
        "seconds_per_rate": seconds,
        "loop_load": {"period_ms": load_period_s * 1e3, "snapshot_encodes": load_encodes,
                      "busy_fraction": load.busy_fraction},
        "rows": [*ours, theirs],
        "goal": {
            "skyhelm_50hz_p99_abs_error_ms": ours_50.get("abs_error_p99_ms"),
            "mavsdk_20hz_p99_abs_error_ms": theirs.get("abs_error_p99_ms"),
            "jitter_met": goal_jitter,
            "no_gap_over_100ms": goal_gaps,
        },
        "machine": machine_info(load_average_before),
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="measuring time per rate")
    parser.add_argument("--load-period-ms", type=float, default=LOAD_PERIOD_S * 1e3,
                        help="how often the load task runs")
    parser.add_argument("--load-encodes", type=int, default=LOAD_ENCODES,
                        help="snapshot JSON encodes per load run (0 = no load)")
    args = parser.parse_args(argv)
    result = asyncio.run(run(args.seconds, args.load_period_ms / 1e3, args.load_encodes))
    print_table(result["rows"])
    goal = result["goal"]
    print(f"\nloop load: {result['loop_load']['busy_fraction'] * 100:.0f}% busy encoding snapshots;"
          f" machine load average {result['machine']['load_average_before'][0]:.1f} before, "
          f"{result['machine']['load_average_after'][0]:.1f} after")
    print(f"goal p99 |interval-period|: SkyHelm 50 Hz "
          f"{goal['skyhelm_50hz_p99_abs_error_ms']:.2f} ms vs MAVSDK 20 Hz "
          f"{goal['mavsdk_20hz_p99_abs_error_ms']:.2f} ms -> "
          f"{'met' if goal['jitter_met'] else 'NOT met'}; no gap > 100 ms: "
          f"{'yes' if goal['no_gap_over_100ms'] else 'NO'}")
    write_results("stream_jitter", result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
