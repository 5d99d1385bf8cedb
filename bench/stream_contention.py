"""Setpoint streams on a busy companion computer: SkyHelm vs MAVSDK in the same run.

A stand-in vehicle (bench/_receiver.py) timestamps every setpoint at real-time priority
(SCHED_FIFO 20), as a vehicle on its own hardware is untouched by the load of the computer
that streams to it. ``skyhelm serve`` streams 50 Hz (started through the REST API) and
MAVSDK's offboard plugin (mavsdk_server) 20 Hz to it at once, under:

- ``quiet``: nothing added (the machine may be shared: only ratios within a run count);
- ``busy``: 8 busy-loop processes per core at normal priority;
- ``busy+load``: the same plus SkyHelm's own load (50 WebSocket telemetry clients at
  10 Hz, 50 REST reads/s, as bench/stream_vs_mavsdk.py makes it);
- ``one-core``: the server (its sender process too) and mavsdk_server pinned to core 0
  with 4 busy loops there (a small companion computer; the vehicle is not pinned).

Once per server send path (``--senders``: ``process``, the default, and ``thread``, the
sender thread it replaces). Then, on the default path and under ``busy``: 50 stand-in
vehicles on one udpin link, each streamed at 20 Hz, and MANUAL_CONTROL at 25 Hz.

Figures: p50/p99 |interval − period|, the largest interval, gaps over 100/250/500 ms.
Goals: busy and busy+load, SkyHelm's p99 ≤ 0.5× MAVSDK's and no gap > 100 ms; one-core, no
gap > 250 ms; quiet, p99 ≤ 0.5× MAVSDK's; 50 vehicles under busy, every stream p99 ≤ 5 ms.

    .venv/bin/python -m bench.stream_contention [--seconds 10] [--senders process,thread]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import sys
import time
from collections.abc import AsyncIterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx

from bench._results import machine_info, write_results
from bench._serve import served
from bench.stream_vs_mavsdk import (
    MAVSDK_RATE_HZ,
    SKYHELM_RATE_HZ,
    TOKEN,
    ReceiverProcess,
    interval_figures,
    loaded,
    mavsdk_streaming,
    skyhelm_serve,
    start_skyhelm_stream,
)

if TYPE_CHECKING:
    from bench._report import Section

RECEIVER_RT_PRIORITY = 20
BUSY_PER_CORE = 8
ONE_CORE_BUSY = 4
ONE_CORE = 0
SCENARIOS = ("quiet", "busy", "busy+load", "one-core")
FLEET_VEHICLES = 50
FLEET_RATE_HZ = 20.0
FLEET_TELEMETRY_HZ = 5.0
FLEET_P99_LIMIT_MS = 5.0
MANUAL_CONTROL_RATE_HZ = 25.0
STICKS_RENEW_S = 0.2
SETTLE_S = 1.0
HEADERS = {"Authorization": f"Bearer {TOKEN}"}


# -- load and pinning --

@contextlib.contextmanager
def busy_loops(count: int, cpus: set[int] | None = None) -> Any:
    """``count`` processes spinning in Python at normal priority (on ``cpus`` if given)."""
    import subprocess

    def normal_priority() -> None:
        # never a real-time busy loop, whatever this process's thread runs at
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        if cpus:
            os.sched_setaffinity(0, cpus)

    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"],
                              preexec_fn=normal_priority) for _ in range(count)]
    try:
        yield procs
    finally:
        for proc in procs:
            proc.kill()
        for proc in procs:
            proc.wait()


def _tree(pid: int) -> list[int]:
    """``pid`` and its descendants."""
    found = [pid]
    for task in Path(f"/proc/{pid}/task").glob("*"):
        with contextlib.suppress(OSError):
            for child in (task / "children").read_text().split():
                found += _tree(int(child))
    return found


def pin(pids: Sequence[int], cpus: set[int]) -> None:
    """Every thread of every process in ``pids`` and their descendants onto ``cpus``."""
    for pid in pids:
        for member in _tree(pid):
            for task in Path(f"/proc/{member}/task").glob("*"):
                with contextlib.suppress(OSError):
                    os.sched_setaffinity(int(task.name), cpus)


def mavsdk_server_pid() -> int | None:
    for pid in _tree(os.getpid())[1:]:
        with contextlib.suppress(OSError):
            if Path(f"/proc/{pid}/comm").read_text().strip().startswith("mavsdk_server"):
                return pid
    return None


# -- phases --

async def measure_pair(receiver: ReceiverProcess, seconds: float, mavsdk_key: str
                       ) -> dict[str, Any]:
    await receiver.reset()
    await asyncio.sleep(seconds)
    arrivals = await receiver.arrivals()
    return {"skyhelm": interval_figures(arrivals.get("255/190", []), SKYHELM_RATE_HZ),
            "mavsdk": interval_figures(arrivals.get(mavsdk_key, []), MAVSDK_RATE_HZ)}


async def scenario(name: str, receiver: ReceiverProcess, seconds: float, mavsdk_key: str,
                   server_pid: int, base: str) -> dict[str, Any]:
    cores = set(range(os.cpu_count() or 1))
    if name == "one-core":
        mavsdk_pid = mavsdk_server_pid()
        pin([server_pid] + ([mavsdk_pid] if mavsdk_pid else []), {ONE_CORE})
        loops = busy_loops(ONE_CORE_BUSY, {ONE_CORE})
    elif name in ("busy", "busy+load"):
        loops = busy_loops(BUSY_PER_CORE * len(cores))
    else:
        loops = contextlib.nullcontext()
    try:
        if name == "busy+load":
            # the load at normal priority, as the server's own clients would be
            async with loaded(base, seconds + SETTLE_S + 3.0, nice=0) as facts:
                with loops:
                    await asyncio.sleep(SETTLE_S)
                    figures = await measure_pair(receiver, seconds, mavsdk_key)
            figures["load"] = facts
        else:
            with loops:
                await asyncio.sleep(SETTLE_S)
                figures = await measure_pair(receiver, seconds, mavsdk_key)
    finally:
        if name == "one-core":
            pin([server_pid] + ([mavsdk_pid] if mavsdk_pid else []), cores)
    return {"scenario": name, **figures}


async def fleet_phase(seconds: float, sender: str) -> dict[str, Any]:
    """FLEET_VEHICLES stand-ins on one udpin link, each streamed at FLEET_RATE_HZ, under
    busy loops."""
    port = _free_udp_port()
    command = [sys.executable, "-m", "server.cli", "serve", "--port", "0", "--token", TOKEN,
               "--connect", f"udpin:127.0.0.1:{port}", "--rate-hz", str(FLEET_RATE_HZ),
               "--no-scene", "--no-tlog", "--log-level", "warning", "--lease-ttl-s", "60"]
    async with served(command, {"SKYHELM_STREAM_SENDER": sender}) as (_proc, base), \
            ReceiverProcess.running(
                "--vehicles", str(FLEET_VEHICLES), "--connect", str(port),
                "--rt-priority", str(RECEIVER_RT_PRIORITY),
                telemetry_hz=FLEET_TELEMETRY_HZ) as receiver, \
            httpx.AsyncClient(base_url=base, headers=HEADERS, timeout=20) as client:
        for _ in range(300):
            listed = (await client.get("/api/v1/vehicles")).json()
            if len(listed) >= FLEET_VEHICLES:
                break
            await asyncio.sleep(0.1)
        hold = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -5.0}
        for sysid in range(1, FLEET_VEHICLES + 1):
            lease = (await client.post(f"/api/v1/vehicles/{sysid}/control")).json()["lease_id"]
            sent = await client.put(f"/api/v1/vehicles/{sysid}/setpoint", json=hold,
                                    headers={"X-Lease-Id": lease})
            sent.raise_for_status()
        with busy_loops(BUSY_PER_CORE * (os.cpu_count() or 1)):
            await asyncio.sleep(SETTLE_S)
            await receiver.reset()
            await asyncio.sleep(seconds)
            arrivals = await receiver.arrivals()
    streams = [interval_figures(arrivals.get(f"{sysid}:255/190", []), FLEET_RATE_HZ)
               for sysid in range(1, FLEET_VEHICLES + 1)]
    for figures in streams:
        figures.pop("abs_errors_ms", None)
    p99s = sorted(s.get("abs_error_p99_ms", float("inf")) for s in streams)
    return {"vehicles": FLEET_VEHICLES, "rate_hz": FLEET_RATE_HZ, "sender": sender,
            "streams": streams, "worst_p99_ms": p99s[-1], "median_p99_ms": p99s[len(p99s) // 2],
            "largest_gap_ms": max(s.get("interval_max_ms", 0.0) for s in streams),
            "gaps_over_100ms": sum(s.get("gaps_over_100ms", 0) for s in streams),
            "every_stream_p99_met": p99s[-1] <= FLEET_P99_LIMIT_MS}


async def manual_control_phase(receiver: ReceiverProcess, base: str, lease: str,
                               seconds: float) -> dict[str, Any]:
    """MANUAL_CONTROL at 25 Hz under busy loops, the sticks renewed as a page does."""
    async with httpx.AsyncClient(base_url=base, headers=HEADERS, timeout=10) as client:
        # the stream's lease has lapsed by now (no renewals while it streamed): take anew
        taken = (await client.post("/api/v1/vehicles/1/control")).json()
        lease = taken.get("lease_id", lease)
        sticks = {"pitch": 0.1, "roll": 0.0, "yaw": 0.0, "throttle": 0.5}

        async def renew() -> None:
            while True:
                answer = await client.put("/api/v1/vehicles/1/sticks", json=sticks,
                                          headers={"X-Lease-Id": lease})
                if answer.status_code != 200:
                    raise RuntimeError(f"sticks refused: {answer.status_code} {answer.text}")
                await asyncio.sleep(STICKS_RENEW_S)

        # the pilot's page runs on another computer, untouched by this one's busy loops:
        # this thread (the renewals' loop) gets real-time scheduling for the phase
        policy = os.sched_getscheduler(0)
        with contextlib.suppress(OSError):
            # reset on fork: the busy loops and servers started from here stay ordinary
            os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(1))
        renewing = asyncio.create_task(renew())
        try:
            with busy_loops(BUSY_PER_CORE * (os.cpu_count() or 1)):
                await asyncio.sleep(SETTLE_S)
                await receiver.reset()
                await asyncio.sleep(seconds)
                arrivals = await receiver.arrivals()
        finally:
            renewing.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await renewing
            os.sched_setscheduler(0, policy, os.sched_param(0))
            await client.delete("/api/v1/vehicles/1/sticks", headers={"X-Lease-Id": lease})
    figures = interval_figures(arrivals.get("mc:255/190", []), MANUAL_CONTROL_RATE_HZ)
    figures.pop("abs_errors_ms", None)
    return figures


def _free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@contextlib.asynccontextmanager
async def streaming_server(receiver: ReceiverProcess, sender: str
                           ) -> AsyncIterator[tuple[int, str, str]]:
    async with skyhelm_serve(receiver.port, {"SKYHELM_STREAM_SENDER": sender}) as (proc, base):
        async with httpx.AsyncClient(base_url=base, headers=HEADERS, timeout=10) as client:
            lease = await start_skyhelm_stream(client)
        yield proc.pid, base, lease


async def run(seconds: float, senders: Sequence[str], fleet: bool) -> dict[str, Any]:
    load_average_before = os.getloadavg()
    rows: list[dict[str, Any]] = []
    manual: dict[str, Any] = {}
    async with ReceiverProcess.running("--rt-priority", str(RECEIVER_RT_PRIORITY)) as receiver, \
            mavsdk_streaming(receiver.port) as mavsdk_key:
        for sender in senders:
            async with streaming_server(receiver, sender) as (pid, base, lease):
                for name in SCENARIOS:
                    row = await scenario(name, receiver, seconds, mavsdk_key, pid, base)
                    rows.append({"sender": sender, **row})
                    _print_row(rows[-1])
                if sender == senders[0]:
                    manual = await manual_control_phase(receiver, base, lease, seconds)
                    print(f"manual control 25 Hz under busy: {_short(manual)}", flush=True)
    fleet_result = await fleet_phase(seconds, senders[0]) if fleet else None
    if fleet_result is not None:
        print(f"{FLEET_VEHICLES} vehicles at {FLEET_RATE_HZ:g} Hz under busy: worst p99 "
              f"{fleet_result['worst_p99_ms']:.2f} ms, median p99 "
              f"{fleet_result['median_p99_ms']:.2f} ms, largest gap "
              f"{fleet_result['largest_gap_ms']:.1f} ms", flush=True)
    return {"seconds_per_phase": seconds, "senders": list(senders),
            "receiver_rt_priority": RECEIVER_RT_PRIORITY, "busy_per_core": BUSY_PER_CORE,
            "one_core_busy": ONE_CORE_BUSY, "rows": rows, "manual_control": manual,
            "fleet": fleet_result, "goals": goals(rows, fleet_result),
            "machine": machine_info(load_average_before)}


def goals(rows: list[dict[str, Any]], fleet: dict[str, Any] | None) -> dict[str, Any]:
    """The goals on the first sender's rows."""
    first = rows[0]["sender"] if rows else None
    out: dict[str, Any] = {"sender": first}
    for row in (r for r in rows if r["sender"] == first):
        ours = row["skyhelm"].get("abs_error_p99_ms", float("inf"))
        theirs = row["mavsdk"].get("abs_error_p99_ms", float("nan"))
        ratio = ours / theirs if theirs and theirs > 0 else None
        gap_limit = "gaps_over_250ms" if row["scenario"] == "one-core" else "gaps_over_100ms"
        goal: dict[str, Any] = {"ratio": ratio, "no_gap": row["skyhelm"].get(gap_limit, 1) == 0}
        if row["scenario"] != "one-core":
            goal["ratio_met"] = ratio is not None and ratio <= 0.5
        out[row["scenario"]] = goal
    if fleet is not None:
        out["fleet_every_stream_p99_met"] = fleet["every_stream_p99_met"]
    return out


def _short(r: dict[str, Any]) -> str:
    return (f"recv {r.get('received', 0):4d} p50 {r.get('abs_error_p50_ms', float('nan')):6.2f} "
            f"p99 {r.get('abs_error_p99_ms', float('nan')):6.2f} ms max "
            f"{r.get('interval_max_ms', float('nan')):6.1f} ms gaps>100/250/500 "
            f"{r.get('gaps_over_100ms', 0)}/{r.get('gaps_over_250ms', 0)}/"
            f"{r.get('gaps_over_500ms', 0)}")


def _print_row(row: dict[str, Any]) -> None:
    for client in ("skyhelm", "mavsdk"):
        print(f"{row['sender']:8} {row['scenario']:10} {client:8} {_short(row[client])}",
              flush=True)


def report(result: dict[str, Any]) -> Section | None:
    from bench._report import Section, pyplot, save_figure

    rows = result.get("rows") or []
    if not rows:
        return None
    plt = pyplot()
    fig, axes = plt.subplots(1, len(SCENARIOS), figsize=(18, 4), sharey=True)
    for ax, name in zip(axes, SCENARIOS, strict=True):
        for row in (r for r in rows if r["scenario"] == name):
            for client, style in (("skyhelm", "-"), ("mavsdk", ":")):
                errors = row[client].get("abs_errors_ms") or []
                if not errors or (client == "mavsdk" and row["sender"] != rows[0]["sender"]):
                    continue
                label = (f"SkyHelm 50 Hz ({row['sender']})" if client == "skyhelm"
                         else "MAVSDK 20 Hz")
                ys = [max(1.0 - (i + 1) / len(errors), 1e-4) for i in range(len(errors))]
                ax.step([max(e, 1e-3) for e in errors], ys, style, where="post", label=label)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("|interval − period| at the vehicle (ms)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("fraction of intervals above")
    fig.suptitle("Setpoint streams on a busy machine (receiver at SCHED_FIFO 20), same run")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    machine = result.get("machine", {})
    figure = save_figure(fig, "stream_contention", "Stream lateness under contention", machine)
    plt.close(fig)
    lines = ["| sender | machine | client | p50 \\|err\\| ms | p99 \\|err\\| ms | p99 ratio "
             "| largest interval ms | gaps > 100 / 250 / 500 ms |",
             "|---|---|---|---|---|---|---|---|"]
    for row in rows:
        theirs = row["mavsdk"].get("abs_error_p99_ms")
        for client in ("skyhelm", "mavsdk"):
            r = row[client]
            ratio = (f"{r['abs_error_p99_ms'] / theirs:.2f}"
                     if client == "skyhelm" and theirs and "abs_error_p99_ms" in r else "")
            lines.append(
                f"| {row['sender']} | {row['scenario']} | {client} {r['rate_hz']:g} Hz | "
                f"{r.get('abs_error_p50_ms', float('nan')):.2f} | "
                f"{r.get('abs_error_p99_ms', float('nan')):.2f} | {ratio} | "
                f"{r.get('interval_max_ms', float('nan')):.1f} | {r.get('gaps_over_100ms', 0)} "
                f"/ {r.get('gaps_over_250ms', 0)} / {r.get('gaps_over_500ms', 0)} |")
    fleet = result.get("fleet")
    manual = result.get("manual_control") or {}
    extra = []
    if fleet:
        extra.append(
            f"- {fleet['vehicles']} vehicles at {fleet['rate_hz']:g} Hz under busy "
            f"({fleet['sender']}): worst stream p99 {fleet['worst_p99_ms']:.2f} ms, median "
            f"stream p99 {fleet['median_p99_ms']:.2f} ms, largest interval "
            f"{fleet['largest_gap_ms']:.1f} ms, gaps over 100 ms {fleet['gaps_over_100ms']} "
            f"(goal every p99 ≤ {FLEET_P99_LIMIT_MS:g} ms: "
            f"{'met' if fleet['every_stream_p99_met'] else 'not met'}).")
    if manual:
        extra.append(
            f"- MANUAL_CONTROL at 25 Hz under busy: p50 {manual.get('abs_error_p50_ms', 0):.2f}"
            f" ms, p99 {manual.get('abs_error_p99_ms', 0):.2f} ms, largest interval "
            f"{manual.get('interval_max_ms', 0):.1f} ms, gaps over 100 ms "
            f"{manual.get('gaps_over_100ms', 0)}.")
    markdown = (
        "The stand-in vehicle timestamps at real-time priority; busy = "
        f"{result['busy_per_core']} busy-loop processes per core, one-core = the server and "
        f"mavsdk_server pinned to one core with {result['one_core_busy']} busy loops. The "
        "machine is shared, so only figures of the same run compare (the ratio column: "
        "SkyHelm's p99 over MAVSDK's in the same seconds). Goals: busy and busy+load ratio "
        "≤ 0.5 and no gap over 100 ms; one-core no gap over 250 ms; quiet ratio ≤ 0.5.\n\n"
        + "\n".join(lines) + "\n\n" + "\n".join(extra) + "\n")
    return Section(title="Setpoint streams on a busy machine", order=11, markdown=markdown,
                   figures=[figure])


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="measuring time per phase")
    parser.add_argument("--quick", action="store_true", help="3 s phases, the process only")
    parser.add_argument("--senders", default="process,thread",
                        help="server send paths (SKYHELM_STREAM_SENDER values)")
    parser.add_argument("--no-fleet", action="store_true", help="leave out the 50 vehicles")
    parser.add_argument("--fleet-only", action="store_true",
                        help="only the 50 vehicles (printed, not written)")
    args = parser.parse_args(argv)
    senders = ["process"] if args.quick else [s for s in args.senders.split(",") if s]
    import mavsdk_grpc  # noqa: F401  (its loop policy, before the loop starts)

    if args.fleet_only:
        fleet = asyncio.run(fleet_phase(args.seconds, senders[0]))
        print({k: v for k, v in fleet.items() if k != "streams"})
        return 0

    started = time.monotonic()
    result = asyncio.run(run(3.0 if args.quick else args.seconds, senders, not args.no_fleet))
    print(f"goals: {result['goals']}  ({time.monotonic() - started:.0f} s)")
    write_results("stream_contention", result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
