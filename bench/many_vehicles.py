"""Many vehicles on one server: N simulated quads (1, 5, 10, 25, 50), each with its own
20 Hz offboard setpoint stream from one `skyhelm serve`, and the page's telemetry live.

For each N it starts the vehicles in ceil(N / 16) processes (bench._sim_tap: the simulated
vehicles of `python -m sim --count N`, which also time each SET_POSITION_TARGET_LOCAL_NED
with its datagram's kernel receive timestamp), then `skyhelm serve --connect` to all of
them, takes control of every vehicle and puts a hold setpoint on each (the vehicles stay
landed and disarmed: PX4 takes offboard setpoints in any state, and the server streams
them all the same). Over MEASURE_S seconds it measures:

- every stream at its receiver: |interval - 50 ms| p99 per stream (the worst stream is the
  claim) and the largest gap;
- the server's CPU share of one core and the vehicle processes' (utime + stime, /proc);
- the page: one WebSocket as the page's map opens it (all vehicles, 4 Hz) and one as its
  vehicle panel does (vehicle 1, 10 Hz): states per vehicle per second and vehicle -> page
  latency (receive time minus the state's `updated_s`, same CLOCK_MONOTONIC).

Goal (issue 14): 50 vehicles, every stream p99 error <= 5 ms, no gap > 200 ms, page live.

    .venv/bin/python -m bench.many_vehicles [--counts 1,5,10,25,50] [--seconds 8] [--quick]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
from websockets.asyncio.client import connect

from bench._results import machine_info, write_results
from bench._serve import cpu_seconds, percentile, served
from sim.process.cli import VEHICLES_PER_PROCESS
from sim.process.sim_processes import split_instances

if TYPE_CHECKING:
    from bench._report import Section

PROJECT_ROOT = Path(__file__).resolve().parent.parent
TOKEN = "bench-token-0123456789"
STREAM_RATE_HZ = 20.0
PAGE_ALL_RATE_HZ = 4.0  # web/map.js OTHERS_RATE_HZ: the map's socket for every vehicle
PAGE_ONE_RATE_HZ = 10.0  # web/api.js default: the panel's socket for the chosen vehicle
WARMUP_S = 2.0
DISCOVERY_S = 60.0
GOAL_P99_ERROR_MS = 5.0
GOAL_MAX_GAP_MS = 200.0
# the page is live when every vehicle's state arrives at ≥ this share of the asked rate
PAGE_LIVE_SHARE = 0.8
CLK_TCK = os.sysconf("SC_CLK_TCK")


def stream_figures(arrivals: list[float], period_s: float) -> dict[str, Any]:
    intervals = [b - a for a, b in itertools.pairwise(arrivals)]
    errors_ms = [abs(i - period_s) * 1000.0 for i in intervals]
    return {
        "setpoints": len(arrivals),
        "p99_error_ms": percentile(errors_ms, 99),
        "max_gap_ms": max(intervals) * 1000.0 if intervals else None,
    }


# A tap's report is one JSON line with every interval it timed (tens of thousands).
TAP_LINE_LIMIT_BYTES = 64 * 1024 * 1024


class TapProcess:
    """One bench._sim_tap process and its line protocol."""

    def __init__(self, proc: asyncio.subprocess.Process) -> None:
        self.proc = proc

    @classmethod
    async def start(cls, first: int, count: int) -> TapProcess:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "bench._sim_tap", "--first", str(first), "--count", str(count),
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE, cwd=PROJECT_ROOT,
            limit=TAP_LINE_LIMIT_BYTES,
        )
        return cls(proc)

    async def line(self) -> dict[str, Any]:
        assert self.proc.stdout is not None
        text = await asyncio.wait_for(self.proc.stdout.readline(), 60)
        if not text:
            raise RuntimeError(f"sim tap exited with code {await self.proc.wait()}")
        message: dict[str, Any] = json.loads(text)
        return message

    def say(self, word: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(f"{word}\n".encode())

    async def stop(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            await asyncio.wait_for(self.proc.wait(), 10)
        except TimeoutError:
            self.proc.kill()
            await self.proc.wait()


def skyhelm_serve(
    urls: list[str], scene: bool, profile: Path | None = None
) -> contextlib.AbstractAsyncContextManager[tuple[asyncio.subprocess.Process, str]]:
    profiler = ["-m", "cProfile", "-o", str(profile)] if profile is not None else []
    return served([
        sys.executable, *profiler, "-m", "server.cli", "serve", "--port", "0", "--token", TOKEN,
        "--rate-hz", str(STREAM_RATE_HZ), "--no-tlog", "--log-level", "warning",
        *([] if scene else ["--no-scene"]),
        *(arg for url in urls for arg in ("--connect", url)),
    ])


class PageProbe:
    """The page's two telemetry sockets: states per vehicle and their latency."""

    def __init__(self) -> None:
        self.counts: dict[int, int] = {}
        self.latencies_ms: list[float] = []
        self.panel_states = 0
        self.panel_latencies_ms: list[float] = []
        # events the page shows: a vehicle lost, a stream stopped (kind -> count)
        self.events: dict[str, int] = {}

    def reset(self) -> None:
        self.events.clear()
        self.counts.clear()
        self.latencies_ms.clear()
        self.panel_states = 0
        self.panel_latencies_ms.clear()

    async def watch(self, url: str, panel: bool) -> None:
        async with connect(url, max_size=2**24) as ws:
            async for text in ws:
                now = time.monotonic()
                message = json.loads(text)
                if message.get("type") == "event" and not panel:
                    kind = str(message.get("kind"))
                    if kind == "connection" and message["data"].get("connected") is False:
                        kind = "link_lost"
                    self.events[kind] = self.events.get(kind, 0) + 1
                if message.get("type") != "state":
                    continue
                latency_ms = (now - message["updated_s"]) * 1000.0
                if panel:
                    self.panel_states += 1
                    self.panel_latencies_ms.append(latency_ms)
                else:
                    sysid = int(message["vehicle"])
                    self.counts[sysid] = self.counts.get(sysid, 0) + 1
                    self.latencies_ms.append(latency_ms)


async def take_control_and_stream(client: httpx.AsyncClient, sysid: int) -> None:
    lease = (await client.post(f"/api/v1/vehicles/{sysid}/control")).json()["lease_id"]
    hold = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": 0.0}
    sent = await client.put(
        f"/api/v1/vehicles/{sysid}/setpoint", json=hold, headers={"X-Lease-Id": lease}
    )
    sent.raise_for_status()


async def measure(
    count: int, seconds: float, scene: bool, profile: Path | None = None
) -> dict[str, Any]:
    processes = math.ceil(count / VEHICLES_PER_PROCESS)
    taps = [await TapProcess.start(first, n)
            for first, n in split_instances(0, count, processes)]
    try:
        readies = [await tap.line() for tap in taps]
        urls = [f"udpout:127.0.0.1:{inst['api_local_port']}"
                for ready in readies for inst in ready["instances"]]
        sysids = [int(inst["sysid"]) for ready in readies for inst in ready["instances"]]
        async with skyhelm_serve(urls, scene, profile) as (server, base):
            headers = {"Authorization": f"Bearer {TOKEN}"}
            async with httpx.AsyncClient(base_url=base, headers=headers, timeout=30) as client:
                deadline = time.monotonic() + DISCOVERY_S
                while len(heard := (await client.get("/api/v1/vehicles")).json()) < count:
                    if time.monotonic() > deadline:
                        break  # measured with the vehicles heard; the row says how many
                    await asyncio.sleep(0.2)
                heard_sysids = {int(v["sysid"]) for v in heard}
                started = await asyncio.gather(
                    *(take_control_and_stream(client, s) for s in sysids if s in heard_sysids),
                    return_exceptions=True)
                streams_refused = sum(1 for outcome in started if outcome is not None)
                ws_base = base.replace("http://", "ws://") + "/api/v1/ws/telemetry"
                probe = PageProbe()
                watchers = [
                    asyncio.create_task(probe.watch(
                        f"{ws_base}?rate_hz={PAGE_ALL_RATE_HZ:g}&token={TOKEN}", panel=False)),
                    asyncio.create_task(probe.watch(
                        f"{ws_base}?vehicle={sysids[0]}&rate_hz={PAGE_ONE_RATE_HZ:g}"
                        f"&token={TOKEN}", panel=True)),
                ]
                await asyncio.sleep(WARMUP_S)
                for tap in taps:
                    tap.say("reset")
                probe.reset()
                server_cpu0, wall0 = cpu_seconds(server.pid), time.monotonic()
                await asyncio.sleep(seconds)
                for tap in taps:
                    tap.say("report")
                wall_s = time.monotonic() - wall0
                server_cpu_share = (cpu_seconds(server.pid) - server_cpu0) / wall_s
                reports = [await tap.line() for tap in taps]
                for watcher in watchers:
                    watcher.cancel()
                await asyncio.gather(*watchers, return_exceptions=True)
    finally:
        for tap in taps:
            await tap.stop()
    row = summarise(count, processes, reports, probe, wall_s, server_cpu_share)
    row["vehicles_heard_by_server"] = len(heard_sysids)
    row["streams_refused"] = streams_refused
    return row


def summarise(
    count: int, processes: int, reports: list[dict[str, Any]], probe: PageProbe,
    wall_s: float, server_cpu_share: float,
) -> dict[str, Any]:
    period_s = 1.0 / STREAM_RATE_HZ
    streams = {sysid: stream_figures(times, period_s)
               for report in reports for sysid, times in report["arrivals"].items()}
    p99s = [s["p99_error_ms"] for s in streams.values() if s["p99_error_ms"] is not None]
    gaps = [s["max_gap_ms"] for s in streams.values() if s["max_gap_ms"] is not None]
    silent = [sysid for sysid, s in streams.items() if s["p99_error_ms"] is None]
    rates = [probe.counts.get(int(sysid), 0) / wall_s for sysid in streams]
    sims_cpu_share = sum(r["cpu_s"] / r["wall_s"] for r in reports)
    sim_over_wall = min(r["sim_over_wall"] for r in reports)
    sim_max_lag_ms = max(r["loop_max_lag_s"] for r in reports) * 1000.0
    # over the streams that ran; a silent one (never started, or stopped) fails the goal
    worst_p99 = max(p99s) if p99s else None
    worst_gap = max(gaps) if gaps else None
    page_live = bool(rates) and min(rates) >= PAGE_LIVE_SHARE * PAGE_ALL_RATE_HZ
    return {
        "vehicles": count,
        "vehicle_processes": processes,
        "seconds": round(wall_s, 2),
        "streams_silent": silent,
        "stream_p99_error_ms_worst": worst_p99,
        "stream_p99_error_ms_median": percentile(p99s, 50),
        "stream_max_gap_ms": worst_gap,
        "server_cpu_share_of_one_core": round(server_cpu_share, 4),
        "sims_cpu_share_of_one_core": round(sims_cpu_share, 4),
        # the slowest vehicle process: sim time per wall time, its stepping loop's worst lag
        "sims_sim_over_wall_min": round(sim_over_wall, 4),
        "sims_loop_max_lag_ms": round(sim_max_lag_ms, 1),
        "page_all_states_per_vehicle_hz_min": round(min(rates), 2) if rates else None,
        "page_all_latency_p50_ms": percentile(probe.latencies_ms, 50),
        "page_all_latency_p99_ms": percentile(probe.latencies_ms, 99),
        "page_panel_states_hz": round(probe.panel_states / wall_s, 2),
        "page_panel_latency_p99_ms": percentile(probe.panel_latencies_ms, 99),
        "page_live": page_live,
        "page_events": dict(probe.events),
        "goal_met": not silent and worst_p99 is not None and worst_gap is not None
        and worst_p99 <= GOAL_P99_ERROR_MS and worst_gap <= GOAL_MAX_GAP_MS and page_live,
    }


def _ms(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.1f} ms"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--counts", default="1,5,10,25,50")
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--no-scene", action="store_true", help="serve without the 3D scene")
    parser.add_argument("--profile", type=Path,
                        help="run the server under cProfile, writing FILE.<vehicles>")
    parser.add_argument("--quick", action="store_true", help="smoke run: 1 and 5 vehicles, 3 s")
    args = parser.parse_args()
    counts = [1, 5] if args.quick else [int(c) for c in args.counts.split(",")]
    seconds = 3.0 if args.quick else args.seconds
    load_before = os.getloadavg()
    rows = []
    for count in counts:
        profile = args.profile.with_suffix(f".{count}") if args.profile else None
        row = asyncio.run(measure(count, seconds, scene=not args.no_scene, profile=profile))
        rows.append(row)
        print(
            f"{count:3d} vehicles in {row['vehicle_processes']} processes: stream p99 error "
            f"worst {_ms(row['stream_p99_error_ms_worst'])} (median "
            f"{_ms(row['stream_p99_error_ms_median'])}), max gap "
            f"{_ms(row['stream_max_gap_ms'])}; server "
            f"{100 * row['server_cpu_share_of_one_core']:.0f} % of a core, vehicles "
            f"{100 * row['sims_cpu_share_of_one_core']:.0f} % (sim/wall "
            f"{row['sims_sim_over_wall_min']}, loop lag max {row['sims_loop_max_lag_ms']} ms); "
            "page: "
            f"{row['page_all_states_per_vehicle_hz_min']} states/s per vehicle (min), p99 "
            f"{_ms(row['page_all_latency_p99_ms'])}, live: {row['page_live']}, events "
            f"{row['page_events']}; "
            f"goal met: {row['goal_met']}",
            flush=True,
        )
    result = {
        "machine": machine_info(load_before),
        "stream_rate_hz": STREAM_RATE_HZ,
        "scene": not args.no_scene,
        "rows": rows,
        "goal": {"p99_error_ms": GOAL_P99_ERROR_MS, "max_gap_ms": GOAL_MAX_GAP_MS,
                 "vehicles": 50},
    }
    write_results("many_vehicles", result)
    return 0


def report(result: dict[str, Any]) -> Section | None:
    rows = result.get("rows") or []
    if not rows:
        return None
    from bench._report import Section, pyplot, save_figure

    plt = pyplot()

    machine = result["machine"]
    n = [r["vehicles"] for r in rows]
    nan = float("nan")
    fig, (quality, cpu) = plt.subplots(1, 2, figsize=(10, 3.8))
    quality.plot(n, [r["stream_p99_error_ms_worst"] or nan for r in rows], "o-",
                 label="worst stream p99 |interval − 50 ms|")
    quality.plot(n, [r["stream_p99_error_ms_median"] or nan for r in rows], "s--",
                 label="median stream p99 |interval − 50 ms|")
    quality.axhline(GOAL_P99_ERROR_MS, color="#c33", lw=0.8, ls=":", label="goal")
    quality.set_xlabel("vehicles on one server (20 Hz stream each)")
    quality.set_ylabel("ms, at the vehicles' sockets")
    quality.legend(fontsize=7)
    cpu.plot(n, [100 * r["server_cpu_share_of_one_core"] for r in rows], "o-", label="server")
    cpu.plot(n, [100 * r["sims_cpu_share_of_one_core"] for r in rows], "s-",
             label="simulated vehicles (all processes)")
    cpu.set_xlabel("vehicles")
    cpu.set_ylabel("% of one core")
    cpu.legend(fontsize=7)
    fig.tight_layout()
    figure = save_figure(fig, "many_vehicles", "Stream quality and CPU vs vehicles", machine)
    plt.close(fig)
    first, last = rows[0], rows[-1]
    growth = last["server_cpu_share_of_one_core"] / max(first["server_cpu_share_of_one_core"], 1e-9)
    per_vehicle = ((last["server_cpu_share_of_one_core"] - first["server_cpu_share_of_one_core"])
                   / max(1, last["vehicles"] - first["vehicles"]))
    lines = [
        f"One server, {last['vehicles']} simulated vehicles each streaming 20 Hz setpoints: "
        f"the worst stream's p99 error is {last['stream_p99_error_ms_worst'] or float('nan'):.1f} "
        f"ms ({(last['stream_p99_error_ms_worst'] or 0) / GOAL_P99_ERROR_MS:.2f}× the 5 ms goal), "
        f"largest gap {last['stream_max_gap_ms'] or float('nan'):.0f} ms "
        f"({(last['stream_max_gap_ms'] or 0) / GOAL_MAX_GAP_MS:.2f}× the 200 ms goal).",
        f"Server CPU grows by {100 * per_vehicle:.2f} % of a core per vehicle "
        f"({growth:.1f}× "
        f"from {first['vehicles']} to {last['vehicles']} vehicles).",
        f"Streams silent at {last['vehicles']} vehicles (never started or stopped by a lost "
        f"link): {len(last['streams_silent'])}; vehicles processes kept "
        f"{last.get('sims_sim_over_wall_min', float('nan')):.2f}× real time at worst.",
        f"The page's map socket got every vehicle's state at ≥ "
        f"{last['page_all_states_per_vehicle_hz_min']} Hz of {PAGE_ALL_RATE_HZ:g} Hz asked "
        f"(live: {last['page_live']}).",
    ]
    table = ["", "| vehicles | processes | worst p99 error | max gap | silent streams "
             "| server CPU | vehicles CPU | page states/s per vehicle |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        table.append(
            f"| {r['vehicles']} | {r['vehicle_processes']} | {_ms(r['stream_p99_error_ms_worst'])} "
            f"| {_ms(r['stream_max_gap_ms'])} | {len(r['streams_silent'])} "
            f"| {100 * r['server_cpu_share_of_one_core']:.0f} % "
            f"| {100 * r['sims_cpu_share_of_one_core']:.0f} % "
            f"| {r['page_all_states_per_vehicle_hz_min']} |"
        )
    return Section(title="Many vehicles on one server", order=40,
                   markdown="\n".join(lines + table), figures=[figure])


if __name__ == "__main__":
    raise SystemExit(main())
