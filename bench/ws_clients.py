"""Telemetry fan-out: vehicle → client latency and server CPU against the number of WebSocket
telemetry clients (1, 10, 50, 100, 200), each asking for one vehicle's state at 10 Hz.

One `skyhelm serve` process with its simulated vehicle (the sim is the server's child
process, so the server's CPU figure excludes it); the clients live in other processes
(asyncio, `websockets`): a probe process of up to PROBE_CLIENTS sockets at the server's
priority, whose latency is the server's, and one or two niced processes with the rest
(they stand in for dashboards on other machines; niced they still get the CPU they need
but yield to the server, as remote clients would).

Measured per client count, over a window after a warm-up:
- latency vehicle → client: the client's receive time minus the state's `updated_s`
  (time.monotonic() when the server took in the vehicle's newest message; both processes
  read the same CLOCK_MONOTONIC), p50 / p99 / max, for the probes and for every client;
- messages received vs expected (clients × rate × window);
- server CPU share of one core (utime + stime from /proc/PID/stat) and how long its loop
  thread sat runnable waiting for a core (/proc/PID/schedstat run_delay).

Goal (issue 14): at 100 clients, probe p99 ≤ 20 ms and server ≤ 50 % of one core.

    python -m bench.ws_clients [--quick] [--seconds 8] [--counts 1,10,50,100,200]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import sys
import time
from typing import TYPE_CHECKING, Any

from bench._results import machine_info, write_results
from bench._serve import cpu_seconds, percentile, served
from bench.api_load import CLIENT_NICE, PROJECT_ROOT, TOKEN, runqueue_wait_s

if TYPE_CHECKING:
    from bench._report import Section

COUNTS = (1, 10, 50, 100, 200)
RATE_HZ = 10.0
PROBE_CLIENTS = 4
CLIENTS_PER_PROCESS = 100
WARMUP_S = 2.0
SETTLE_S = 5.0
SECONDS = 8.0
GOAL_CLIENTS = 100
GOAL_P99_MS = 20.0
GOAL_CPU_SHARE = 0.5


# -- the client side (runs in worker processes) -----------------------------------------------


async def _client(
    url: str,
    start_s: float,
    end_s: float,
    latencies_ms: list[float],
    fan_out_ms: list[float],
    counts: list[int],
) -> None:
    from websockets.asyncio.client import connect

    received = 0
    async with connect(url, max_size=2**22, compression=None) as ws:
        while True:
            remaining_s = end_s - time.monotonic()
            if remaining_s <= 0:
                break
            try:
                text = await asyncio.wait_for(ws.recv(), remaining_s)
            except TimeoutError:
                break
            now_s = time.monotonic()
            if not start_s <= now_s < end_s:
                continue
            message = json.loads(text)
            if message.get("type") == "state":
                received += 1
                latencies_ms.append((now_s - message["updated_s"]) * 1000.0)
                # the snapshot was taken min(message_ages_s) after the newest message
                ages_s = message.get("message_ages_s") or {"": 0.0}
                taken_s = message["updated_s"] + min(ages_s.values())
                fan_out_ms.append((now_s - taken_s) * 1000.0)
    counts.append(received)


async def _worker(url: str, clients: int, start_s: float, end_s: float) -> None:
    """`clients` sockets; prints their figures as one JSON line once end_s has passed."""
    latencies_ms: list[float] = []
    fan_out_ms: list[float] = []
    counts: list[int] = []
    cpu_start_s = time.process_time()
    results = await asyncio.gather(
        *(_client(url, start_s, end_s, latencies_ms, fan_out_ms, counts) for _ in range(clients)),
        return_exceptions=True,
    )
    failures = [repr(result) for result in results if isinstance(result, BaseException)]
    cpu_s = time.process_time() - cpu_start_s
    print(
        json.dumps(
            {
                "latencies_ms": latencies_ms,
                "fan_out_ms": fan_out_ms,
                "counts": counts,
                "failures": failures[:3],
                "failed": len(failures),
                "cpu_s": cpu_s,
            }
        ),
        flush=True,
    )


# -- the driver ---------------------------------------------------------------------------------


async def _spawn(url: str, clients: int, start_s: float, end_s: float, nice: int) -> Any:
    def lower_priority() -> None:
        if nice:
            os.nice(nice)

    return await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "bench.ws_clients",
        "--worker-url",
        url,
        "--worker-clients",
        str(clients),
        "--worker-window",
        f"{start_s!r},{end_s!r}",
        stdout=asyncio.subprocess.PIPE,
        cwd=PROJECT_ROOT,
        preexec_fn=lower_priority,
    )


async def _collect(proc: Any) -> dict[str, Any]:
    out, _ = await proc.communicate()
    lines = out.decode().strip().splitlines()
    if not lines:
        return {
            "latencies_ms": [],
            "fan_out_ms": [],
            "counts": [],
            "failures": ["no output"],
            "failed": 1,
        }
    report: dict[str, Any] = json.loads(lines[-1])
    return report


def _summary(latencies_ms: list[float]) -> dict[str, float | None]:
    return {
        "p50_ms": percentile(latencies_ms, 50),
        "p99_ms": percentile(latencies_ms, 99),
        "max_ms": max(latencies_ms) if latencies_ms else None,
    }


async def measure(pid: int, url: str, clients: int, seconds: float) -> dict[str, Any]:
    probes = min(PROBE_CLIENTS, clients)
    rest = clients - probes
    # time for the processes to start and connect before the window opens
    start_s = time.monotonic() + WARMUP_S + 1.5 + 0.01 * clients
    end_s = start_s + seconds
    probe_proc = await _spawn(url, probes, start_s, end_s, 0)
    procs = []
    while rest > 0:
        share = min(rest, CLIENTS_PER_PROCESS)
        procs.append(await _spawn(url, share, start_s, end_s, CLIENT_NICE))
        rest -= share
    await asyncio.sleep(max(0.0, start_s - time.monotonic()))
    cpu_start_s, wait_start_s, wall_start_s = (
        cpu_seconds(pid),
        runqueue_wait_s(pid),
        time.monotonic(),
    )
    await asyncio.sleep(max(0.0, end_s - time.monotonic()))
    wall_s = time.monotonic() - wall_start_s
    cpu_share = (cpu_seconds(pid) - cpu_start_s) / wall_s
    wait_ms_per_s = (runqueue_wait_s(pid) - wait_start_s) / wall_s * 1000.0
    probe = await _collect(probe_proc)
    others = [await _collect(proc) for proc in procs]
    every = [*probe["latencies_ms"]]
    counts = [*probe["counts"]]
    failures = [*probe["failures"]]
    failed = probe["failed"]
    for report in others:
        every.extend(report["latencies_ms"])
        counts.extend(report["counts"])
        failures.extend(report["failures"])
        failed += report["failed"]
    expected = clients * RATE_HZ * seconds
    return {
        "clients": clients,
        "seconds": seconds,
        "probe_clients": probes,
        "probe_latency": _summary(probe["latencies_ms"]),
        # snapshot → client: the server's own path, without the time the vehicle was silent
        "probe_fan_out": _summary(probe["fan_out_ms"]),
        "probe_share_over_goal": sum(ms > GOAL_P99_MS for ms in probe["latencies_ms"])
        / max(1, len(probe["latencies_ms"])),
        "latency": _summary(every),
        "messages_received": sum(counts),
        "messages_expected": expected,
        "received_share": sum(counts) / expected,
        "clients_failed": failed,
        "failures": failures[:3],
        "server_cpu_share_of_one_core": cpu_share,
        "server_loop_runqueue_wait_ms_per_s": wait_ms_per_s,
    }


# `skyhelm serve` as the CLI runs it (asyncio's loop), or with uvloop's loop installed first
_SERVE = "import sys; from server.cli import main; raise SystemExit(main(sys.argv[1:]))"
_SERVE_UVLOOP = (
    "import sys, uvloop; uvloop.install(); from server.cli import main; "
    "raise SystemExit(main(sys.argv[1:]))"
)


def serve(loop: str) -> contextlib.AbstractAsyncContextManager[
    tuple[asyncio.subprocess.Process, str]
]:
    return served([
        sys.executable, "-c", _SERVE_UVLOOP if loop == "uvloop" else _SERVE, "serve",
        "--port", "0", "--token", TOKEN, "--no-scene", "--no-tlog", "--no-access-log",
        "--log-level", "warning",
    ])


async def run(counts: list[int], seconds: float, loop: str) -> list[dict[str, Any]]:
    rows = []
    async with serve(loop) as (proc, base):
        import httpx

        headers = {"Authorization": f"Bearer {TOKEN}"}
        async with httpx.AsyncClient(base_url=base, headers=headers, timeout=10) as client:
            for _ in range(200):
                if (await client.get("/api/v1/vehicles/1")).status_code == 200:
                    break
                await asyncio.sleep(0.1)
        # the simulated vehicle's first seconds (estimator start, parameter and mission
        # downloads) are not its steady telemetry: let them pass before the first count
        await asyncio.sleep(SETTLE_S)
        url = base.replace("http://", "ws://") + (
            f"/api/v1/ws/telemetry?vehicle=1&rate_hz={RATE_HZ:g}&token={TOKEN}"
        )
        for clients in counts:
            row = await measure(proc.pid, url, clients, seconds)
            rows.append(row)
            _print_row(row)
    return rows


def _ms(value: float | None) -> str:
    return "n/a" if value is None else f"{value:6.1f}"


def _print_row(row: dict[str, Any]) -> None:
    probe, every = row["probe_latency"], row["latency"]
    print(
        f"{row['clients']:>4} clients: snapshot→probe p99 {_ms(row['probe_fan_out']['p99_ms'])} "
        f"| vehicle→probe p50 {_ms(probe['p50_ms'])} p99 "
        f"{_ms(probe['p99_ms'])} max {_ms(probe['max_ms'])} ms | all p50 "
        f"{_ms(every['p50_ms'])} p99 {_ms(every['p99_ms'])} ms | probe > {GOAL_P99_MS:g} ms "
        f"{100 * row['probe_share_over_goal']:.1f} % | received "
        f"{100 * row['received_share']:5.1f} % | server CPU "
        f"{100 * row['server_cpu_share_of_one_core']:4.1f} % of a core, waited "
        f"{row['server_loop_runqueue_wait_ms_per_s']:.0f} ms/s"
        + (f" | {row['clients_failed']} clients failed" if row["clients_failed"] else ""),
        flush=True,
    )


def goals(rows: list[dict[str, Any]]) -> dict[str, bool]:
    at_goal = [row for row in rows if row["clients"] == GOAL_CLIENTS]
    if not at_goal:
        return {}
    row = at_goal[0]
    return {
        f"probe p99 at {GOAL_CLIENTS} clients <= {GOAL_P99_MS:g} ms": (
            row["probe_latency"]["p99_ms"] or 1e9
        )
        <= GOAL_P99_MS,
        f"server CPU at {GOAL_CLIENTS} clients <= {GOAL_CPU_SHARE:.0%} of a core": row[
            "server_cpu_share_of_one_core"
        ]
        <= GOAL_CPU_SHARE,
        "every message received (>= 98 %)": all(r["received_share"] >= 0.98 for r in rows),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=SECONDS, help="window per count")
    parser.add_argument("--counts", default=",".join(map(str, COUNTS)))
    parser.add_argument("--quick", action="store_true", help="1 and 10 clients, 3 s each")
    parser.add_argument(
        "--loop", choices=("asyncio", "uvloop"), default="asyncio", help="the server's loop"
    )
    parser.add_argument("--worker-url", help=argparse.SUPPRESS)
    parser.add_argument("--worker-clients", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--worker-window", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker_url:
        start_s, end_s = (float(x) for x in args.worker_window.split(","))
        asyncio.run(_worker(args.worker_url, args.worker_clients, start_s, end_s))
        return 0
    counts = [1, 10] if args.quick else [int(x) for x in args.counts.split(",")]
    seconds = 3.0 if args.quick else args.seconds
    load_before = os.getloadavg()
    rows = asyncio.run(run(counts, seconds, args.loop))
    met = goals(rows)
    result = {
        "rate_hz": RATE_HZ,
        "server_loop": args.loop,
        "rows": rows,
        "goals_met": met,
        "machine": machine_info(load_before),
    }
    write_results("ws_clients" if args.loop == "asyncio" else f"ws_clients_{args.loop}", result)
    for name, ok in met.items():
        print(f"{'met' if ok else 'MISSED'}: {name}")
    return 0 if all(met.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())


def report(result: dict[str, Any]) -> Section | None:
    """Latency and server CPU against the number of clients, for docs/PERFORMANCE.md."""
    from bench._report import Section, pyplot, save_figure

    plt = pyplot()

    rows = sorted(result.get("rows", []), key=lambda row: row["clients"])
    if not rows:
        return None
    machine = result.get("machine", {})
    clients = [row["clients"] for row in rows]

    def series(part: str, key: str) -> list[float]:
        return [row[part][key] if row[part][key] is not None else float("nan") for row in rows]

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    ax.plot(clients, series("probe_latency", "p50_ms"), "o-", label="p50 (probe clients)")
    ax.plot(clients, series("probe_latency", "p99_ms"), "s-", label="p99 (probe clients)")
    ax.plot(clients, series("latency", "p99_ms"), "^--", label="p99 (every client)")
    if all("probe_fan_out" in row for row in rows):
        ax.plot(
            clients,
            series("probe_fan_out", "p99_ms"),
            "v:",
            label="p99 snapshot → probe (server path only)",
        )
    ax.axhline(GOAL_P99_MS, color="#c44", linestyle=":", label=f"goal p99 {GOAL_P99_MS:g} ms")
    ax.set_xscale("log")
    ax.set_xlabel(f"WebSocket telemetry clients ({result.get('rate_hz', RATE_HZ):g} Hz each)")
    ax.set_ylabel("vehicle → client latency (ms)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    latency = save_figure(
        fig,
        "ws_clients_latency",
        "Telemetry latency (server took in the vehicle's message → client received the "
        "state) against the number of clients",
        machine,
    )
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    cpu = [100 * row["server_cpu_share_of_one_core"] for row in rows]
    ax.plot(clients, cpu, "o-", label="server process")
    ax.axhline(100 * GOAL_CPU_SHARE, color="#c44", linestyle=":", label="goal at 100 clients")
    ax.set_xscale("log")
    ax.set_xlabel(f"WebSocket telemetry clients ({result.get('rate_hz', RATE_HZ):g} Hz each)")
    ax.set_ylabel("server CPU (% of one core)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    cpu_figure = save_figure(
        fig, "ws_clients_cpu", "Server CPU against the number of telemetry clients", machine
    )
    plt.close(fig)

    first, last = rows[0], rows[-1]
    messages_ratio = last["clients"] / first["clients"]
    cpu_ratio = last["server_cpu_share_of_one_core"] / max(
        first["server_cpu_share_of_one_core"], 1e-9
    )
    lines = [
        f"One vehicle, {', '.join(map(str, clients))} WebSocket telemetry clients at "
        f"{result.get('rate_hz', RATE_HZ):g} Hz each, server and clients in separate "
        "processes (`python -m bench.ws_clients`). Each tick is snapshotted and encoded once "
        "and the same text goes to every socket, so going from "
        f"{first['clients']} to {last['clients']} clients ({messages_ratio:.0f}× the "
        f"messages) cost the server {cpu_ratio:.1f}× the CPU "
        f"({100 * first['server_cpu_share_of_one_core']:.1f} % → "
        f"{100 * last['server_cpu_share_of_one_core']:.1f} % of one core).",
        "",
        "Latency is vehicle → client (the server took in the vehicle's newest message → a "
        "probe client received the state); a tier's slot waits at most 90 % of an interval for "
        "a new message, so a vehicle silent for longer shows in it. Snapshot → client is the "
        "server's own path alone.",
        "",
        "| clients | p50 ms | p99 ms | p99 ms (all) | snapshot → client p99 ms | received "
        "| server CPU |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        probe, every = row["probe_latency"], row["latency"]
        lines.append(
            f"| {row['clients']} | {_ms(probe['p50_ms']).strip()} | "
            f"{_ms(probe['p99_ms']).strip()} | {_ms(every['p99_ms']).strip()} | "
            f"{_ms(row.get('probe_fan_out', {}).get('p99_ms')).strip()} | "
            f"{100 * row['received_share']:.1f} % | "
            f"{100 * row['server_cpu_share_of_one_core']:.1f} % |"
        )
    lines.append("")
    for name, ok in result.get("goals_met", {}).items():
        lines.append(f"- {'met' if ok else 'missed'}: {name}")
    return Section(
        title="Telemetry fan-out to WebSocket clients",
        order=30,
        markdown="\n".join(lines),
        figures=[latency, cpu_figure],
    )
