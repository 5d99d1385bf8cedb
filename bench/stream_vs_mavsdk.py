"""Setpoint stream regularity at the receiver: SkyHelm's server vs MAVSDK, idle and loaded.

A stand-in vehicle in its own process (bench/_receiver.py) timestamps every
SET_POSITION_TARGET_LOCAL_NED as it arrives, per sender, and sends attitude and position at
50 Hz (live telemetry for the server to decode and fan out). Two senders stream to it at once:
``skyhelm serve --connect udpout:…`` at 50 Hz (a PUT /setpoint through the REST API, as a
user would) and MAVSDK's offboard plugin (mavsdk_server) at its fixed 20 Hz. Each phase
measures both in the same seconds:

- idle: nothing else asks anything of the server;
- loaded: another process (niced, as remote clients would not take the server's cores)
  holds 50 WebSocket telemetry clients at 10 Hz and makes 50 REST reads/s on the server.

The server runs once per variant of its send path: ``process`` (the sender process of
server.link.stream.stream_process, the default), ``thread`` (the sender thread of
server.link.stream.stream_thread), ``loop`` (the stream timed by the event loop;
SKYHELM_STREAM_SENDER=loop) and, with ``--variants``, ``thread-5ms`` (the thread
with CPython's default 5 ms GIL switch interval). Figures per row: p50/p99 of
|interval − period|, the largest interval, gaps over 100 ms, and the lateness samples
for the report's distribution.

The send-path options themselves are measured first, in this process and under the same
synthetic load (its event loop JSON-encoding ~80% of the time and making garbage for the
collector, as a busy server does): the stream timed by the event loop (``loop``), by the
sender thread (``thread``) and by a separate process sending a precomputed frame on its own
deadlines (``process``: what a sender process fed by the server would achieve at best).

Goal (issue 14): loaded, SkyHelm's 50 Hz p99 |interval − period| ≤ MAVSDK's 20 Hz in the
same run; no gap > 100 ms.

    .venv/bin/python -m bench.stream_vs_mavsdk [--seconds 8] [--quick]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import json
import os
import socket
import statistics
import sys
import time
from collections.abc import AsyncIterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx

from bench._results import machine_info, write_results
from bench._serve import cpu_seconds, served

if TYPE_CHECKING:
    from bench._report import Section

PROJECT_ROOT = Path(__file__).resolve().parent.parent
TOKEN = "bench-token-0123456789"
SKYHELM_RATE_HZ = 50.0
MAVSDK_RATE_HZ = 20.0  # MAVSDK's OffboardImpl SEND_INTERVAL_S = 0.05, not configurable
GAP_LIMIT_S = 0.100
WS_CLIENTS = 50
TELEMETRY_RATE_HZ = 10.0
REST_READS_HZ = 50.0
LOAD_NICE = 10
# the stand-in vehicle's attitude and position rate: live telemetry for the server to fan out
VEHICLE_TELEMETRY_HZ = 50.0
LOAD_WARMUP_S = 2.0
# the server's send path per variant: environment of `skyhelm serve`
VARIANTS: dict[str, dict[str, str]] = {
    "process": {"SKYHELM_STREAM_SENDER": "process"},
    "thread": {"SKYHELM_STREAM_SENDER": "thread"},
    "loop": {"SKYHELM_STREAM_SENDER": "loop"},
    "thread-5ms": {"SKYHELM_STREAM_SENDER": "thread", "SKYHELM_STREAM_SWITCH_INTERVAL_MS": "5"},
}
DEFAULT_VARIANTS = ("process", "thread", "loop")


class ReceiverProcess:
    """bench/_receiver.py as a child process, driven over its stdin/stdout."""

    def __init__(self, proc: asyncio.subprocess.Process, port: int) -> None:
        self.proc = proc
        self.port = port

    @classmethod
    @contextlib.asynccontextmanager
    async def running(cls, *args: str, telemetry_hz: float = VEHICLE_TELEMETRY_HZ
                      ) -> AsyncIterator[ReceiverProcess]:
        """The stand-in vehicle; ``args`` are bench/_receiver.py's options."""
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "bench._receiver", "--telemetry-hz", str(telemetry_hz), *args,
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
            limit=1 << 26,  # a report of 50 vehicles' arrivals is one long line
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
    return {
        "rate_hz": rate_hz,
        "received": len(arrivals),
        "measured_rate_hz": len(intervals) / (arrivals[-1] - arrivals[0]),
        "abs_error_p50_ms": _percentile(errors, 0.50) * 1e3,
        "abs_error_p99_ms": _percentile(errors, 0.99) * 1e3,
        "abs_error_mean_ms": statistics.fmean(errors) * 1e3,
        "interval_max_ms": max(intervals) * 1e3,
        "gaps_over_100ms": sum(i > GAP_LIMIT_S for i in intervals),
        "gaps_over_250ms": sum(i > 0.250 for i in intervals),
        "gaps_over_500ms": sum(i > 0.500 for i in intervals),
        # the distribution, for the report (µs resolution is plenty)
        "abs_errors_ms": [round(e * 1e3, 3) for e in errors],
    }


def _percentile(ordered: Sequence[float], q: float) -> float:
    """Nearest-rank percentile of an ascending sequence."""
    return ordered[max(0, min(len(ordered) - 1, int(q * len(ordered) + 0.999999) - 1))]


def _free_tcp_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


# -- the SkyHelm server --

def skyhelm_serve(vehicle_port: int, env: dict[str, str]
                  ) -> contextlib.AbstractAsyncContextManager[
                      tuple[asyncio.subprocess.Process, str]]:
    return served([
        sys.executable, "-m", "server.cli", "serve", "--port", "0", "--token", TOKEN,
        "--connect", f"udpout:127.0.0.1:{vehicle_port}", "--rate-hz", str(SKYHELM_RATE_HZ),
        "--no-scene", "--no-tlog", "--log-level", "warning", "--lease-ttl-s", "30",
    ], env)


async def start_skyhelm_stream(client: httpx.AsyncClient) -> str:
    """Take control of vehicle 1 and stream a hold setpoint; answers the lease id."""
    for _ in range(200):
        if (await client.get("/api/v1/vehicles/1")).status_code == 200:
            break
        await asyncio.sleep(0.1)
    lease = (await client.post("/api/v1/vehicles/1/control")).json()["lease_id"]
    hold = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -5.0}
    sent = await client.put("/api/v1/vehicles/1/setpoint", json=hold,
                            headers={"X-Lease-Id": lease})
    if sent.status_code != 200:
        raise RuntimeError(f"setpoint refused: {sent.status_code} {sent.text}")
    return str(lease)


# -- the load, in its own process --

async def load_worker(base: str, seconds: float) -> None:
    """WS_CLIENTS telemetry sockets at TELEMETRY_RATE_HZ and REST_READS_HZ reads/s."""
    from websockets.asyncio.client import connect

    stop = asyncio.Event()
    received = [0]
    ws_url = base.replace("http://", "ws://") + (
        f"/api/v1/ws/telemetry?vehicle=1&rate_hz={TELEMETRY_RATE_HZ:g}&token={TOKEN}")

    async def telemetry() -> None:
        async with connect(ws_url, max_size=2**22) as ws:
            while not stop.is_set():
                with contextlib.suppress(TimeoutError):
                    json.loads(await asyncio.wait_for(ws.recv(), 1.0))
                    received[0] += 1

    async def reads(client: httpx.AsyncClient) -> None:
        paths = ["/api/v1/vehicles/1", "/api/v1/vehicles", "/api/v1/vehicles/1/stream",
                 "/api/v1/health"]
        start = time.monotonic()
        for k in itertools.count(1):
            if stop.is_set():
                return
            task = asyncio.create_task(client.get(paths[k % len(paths)]))
            task.add_done_callback(lambda t: t.cancelled() or t.exception())
            await asyncio.sleep(max(0.0, start + k / REST_READS_HZ - time.monotonic()))

    headers = {"Authorization": f"Bearer {TOKEN}"}
    async with httpx.AsyncClient(base_url=base, headers=headers, timeout=10) as client:
        tasks = [asyncio.create_task(telemetry()) for _ in range(WS_CLIENTS)]
        tasks.append(asyncio.create_task(reads(client)))
        await asyncio.sleep(seconds)
        stop.set()
        await asyncio.gather(*tasks, return_exceptions=True)
    print(json.dumps({"telemetry_messages": received[0]}), flush=True)


@contextlib.asynccontextmanager
async def loaded(base: str, seconds: float, nice: int = LOAD_NICE
                 ) -> AsyncIterator[dict[str, Any]]:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "bench.stream_vs_mavsdk", "--load-url", base,
        "--seconds", str(seconds), stdout=asyncio.subprocess.PIPE, cwd=PROJECT_ROOT,
        preexec_fn=lambda: os.nice(nice),
    )
    facts: dict[str, Any] = {}
    try:
        await asyncio.sleep(LOAD_WARMUP_S)
        yield facts
    finally:
        try:
            out, _ = await asyncio.wait_for(proc.communicate(), seconds + 30)
        except TimeoutError:  # a starved load worker: its figures are lost, not the run's
            proc.kill()
            out, _ = await proc.communicate()
        lines = out.decode().strip().splitlines()
        facts.update(json.loads(lines[-1]) if lines else {})


# -- the send-path options, under synthetic load in this process --

OPTION_SYSIDS = {"loop": 201, "thread": 202, "process": 203}
SYNTHETIC_BUSY_S = 0.008
SYNTHETIC_IDLE_S = 0.002


def _frame(sysid: int) -> bytes:
    from pymavlink.dialects.v20 import development as mavlink

    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=190)
    return bytes(mav.set_position_target_local_ned_encode(
        0, 1, 1, 1, 2552, 0, 0, -5, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav))


async def synthetic_load(stop: asyncio.Event) -> None:
    """Runs Python on the loop ~80% of the time (JSON of a vehicle-sized document) and
    leaves cyclic garbage behind, so the collector runs too."""
    document = {"vehicles": [{"id": i, "state": {f"k{j}": j * 0.5 for j in range(60)},
                              "events": [str(j) for j in range(20)]} for i in range(20)]}
    while not stop.is_set():
        until = time.perf_counter() + SYNTHETIC_BUSY_S
        while time.perf_counter() < until:
            json.dumps(document)
            cycle: list[Any] = [document]
            cycle.append(cycle)
        await asyncio.sleep(SYNTHETIC_IDLE_S)


def process_sender(port: int, frame_hex: str, rate_hz: float, seconds: float) -> None:
    """The sender process: one precomputed frame on absolute deadlines, nothing else."""
    from server.link.stream.stream_thread import Deadlines

    frame = bytes.fromhex(frame_hex)
    deadlines = Deadlines(1.0 / rate_hz)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        start = time.monotonic()
        next_s = deadlines.rephase(start)
        sock.sendto(frame, ("127.0.0.1", port))
        while next_s < start + seconds:
            time.sleep(max(0.0, next_s - time.monotonic()))
            now = time.monotonic()
            sock.sendto(frame, ("127.0.0.1", port))
            next_s = deadlines.after_tick(now)


async def measure_sender_options(receiver: ReceiverProcess, seconds: float
                                 ) -> list[dict[str, Any]]:
    from pymavlink.dialects.v20 import development as mavlink

    from server.link.stream import streamer as streamer_module
    from server.link.stream.streamer import SetpointStreamer

    rows = []
    dummy = mavlink.MAVLink(None).set_position_target_local_ned_encode(
        0, 1, 1, 1, 2552, 0, 0, -5, 0, 0, 0, 0, 0, 0, 0, 0)
    for option, sysid in OPTION_SYSIDS.items():
        frame = _frame(sysid)
        stop = asyncio.Event()
        load = asyncio.create_task(synthetic_load(stop))
        await asyncio.sleep(0.3)
        await receiver.reset()
        if option == "process":
            proc = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "bench.stream_vs_mavsdk", "--process-sender",
                f"{receiver.port}:{frame.hex()}:{SKYHELM_RATE_HZ}:{seconds}", cwd=PROJECT_ROOT)
            await proc.wait()
        else:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
                streamer_module.SENDER_THREAD = option == "thread"
                streamer = SetpointStreamer(
                    lambda _m, s=sock, f=frame: s.sendto(f, ("127.0.0.1", receiver.port)),
                    rate_hz=SKYHELM_RATE_HZ)
                streamer.stream(dummy)
                await asyncio.sleep(seconds)
                streamer.stop()
        stop.set()
        await load
        arrivals = (await receiver.arrivals()).get(f"{sysid}/190", [])
        rows.append({"option": option, **interval_figures(arrivals, SKYHELM_RATE_HZ)})
    streamer_module.SENDER_THREAD = True
    return rows


# -- MAVSDK --

@contextlib.asynccontextmanager
async def mavsdk_streaming(vehicle_port: int) -> AsyncIterator[str]:
    import mavsdk_grpc as mavsdk
    from mavsdk_grpc.offboard import PositionNedYaw

    drone = mavsdk.System(port=_free_tcp_port())
    await drone.connect(system_address=f"udpout://127.0.0.1:{vehicle_port}")
    try:
        async for state in drone.core.connection_state():
            if state.is_connected:
                break
        await drone.offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -5.0, 0.0))
        await drone.offboard.start()  # MAVSDK stops streaming to a vehicle not in OFFBOARD
        yield f"{drone._sysid}/{drone._compid}"
    finally:
        with contextlib.suppress(Exception):
            drone._stop_mavsdk_server()


async def measure(receiver: ReceiverProcess, seconds: float, mavsdk_key: str,
                  server_pid: int) -> dict[str, Any]:
    await receiver.reset()
    cpu_start, wall_start = cpu_seconds(server_pid), time.monotonic()
    await asyncio.sleep(seconds)
    cpu_share = (cpu_seconds(server_pid) - cpu_start) / (time.monotonic() - wall_start)
    arrivals = await receiver.arrivals()
    return {
        "skyhelm": interval_figures(arrivals.get("255/190", []), SKYHELM_RATE_HZ),
        "mavsdk": interval_figures(arrivals.get(mavsdk_key, []), MAVSDK_RATE_HZ),
        "server_cpu_share_of_one_core": cpu_share,
    }


async def run(seconds: float, variants: Sequence[str]) -> dict[str, Any]:
    load_average_before = os.getloadavg()
    phases: list[dict[str, Any]] = []
    async with ReceiverProcess.running() as receiver:
        options = await measure_sender_options(receiver, seconds / 2)
    async with ReceiverProcess.running() as receiver, \
            mavsdk_streaming(receiver.port) as mavsdk_key:
        for variant in variants:
            async with skyhelm_serve(receiver.port, VARIANTS[variant]) as (proc, base):
                headers = {"Authorization": f"Bearer {TOKEN}"}
                async with httpx.AsyncClient(base_url=base, headers=headers,
                                             timeout=10) as client:
                    await start_skyhelm_stream(client)
                await asyncio.sleep(0.5)
                if variant == variants[0]:
                    idle = await measure(receiver, seconds, mavsdk_key, proc.pid)
                    phases.append({"variant": variant, "load": "idle", **idle})
                async with loaded(base, seconds + LOAD_WARMUP_S + 1.0) as facts:
                    busy = await measure(receiver, seconds, mavsdk_key, proc.pid)
                phases.append({"variant": variant, "load": "loaded", **busy, **facts})
    first_loaded = next(p for p in phases if p["load"] == "loaded")
    ours = first_loaded["skyhelm"].get("abs_error_p99_ms", float("inf"))
    theirs = first_loaded["mavsdk"].get("abs_error_p99_ms", float("-inf"))
    return {
        "seconds_per_phase": seconds,
        "load": {"ws_clients": WS_CLIENTS, "telemetry_rate_hz": TELEMETRY_RATE_HZ,
                 "rest_reads_hz": REST_READS_HZ, "nice": LOAD_NICE},
        "phases": phases,
        "sender_options": options,
        "sender_options_load": {"busy_ms": SYNTHETIC_BUSY_S * 1e3,
                                "idle_ms": SYNTHETIC_IDLE_S * 1e3},
        "goal": {
            "variant": first_loaded["variant"],
            "skyhelm_50hz_loaded_p99_abs_error_ms": ours,
            "mavsdk_20hz_loaded_p99_abs_error_ms": theirs,
            "ratio_skyhelm_over_mavsdk": ours / theirs if theirs > 0 else None,
            "jitter_met": ours <= theirs,
            "no_gap_over_100ms": all(
                p["skyhelm"].get("gaps_over_100ms", 1) == 0
                for p in phases if p["variant"] == first_loaded["variant"]),
        },
        "machine": machine_info(load_average_before),
    }


def print_table(result: dict[str, Any]) -> None:
    print("send path under synthetic load (this process's loop ~80% busy), 50 Hz:")
    for row in result["sender_options"]:
        print(f"  {row['option']:8} recv {row['received']:4d}  p50|err| "
              f"{row.get('abs_error_p50_ms', float('nan')):7.3f} ms  p99|err| "
              f"{row.get('abs_error_p99_ms', float('nan')):7.3f} ms  max "
              f"{row.get('interval_max_ms', float('nan')):6.1f} ms")
    header = (f"{'variant':11} {'load':7} {'client':8} {'Hz':>4} {'recv':>5} "
              f"{'p50|err| ms':>12} {'p99|err| ms':>12} {'max ms':>8} {'gaps':>5} "
              f"{'server cpu':>10}")
    print(header)
    print("-" * len(header))
    for phase in result["phases"]:
        for client in ("skyhelm", "mavsdk"):
            r = phase[client]
            print(f"{phase['variant']:11} {phase['load']:7} {client:8} {r['rate_hz']:4.0f} "
                  f"{r['received']:5d} {r.get('abs_error_p50_ms', float('nan')):12.3f} "
                  f"{r.get('abs_error_p99_ms', float('nan')):12.3f} "
                  f"{r.get('interval_max_ms', float('nan')):8.1f} "
                  f"{r.get('gaps_over_100ms', 0):5d} "
                  f"{phase['server_cpu_share_of_one_core'] * 100:9.0f}%")


def report(result: dict[str, Any]) -> Section | None:
    from bench._report import Section, pyplot, save_figure

    plt = pyplot()

    phases = result.get("phases") or []
    if not phases:
        return None
    machine = result.get("machine", {})
    fig, axes = plt.subplots(1, 3, figsize=(15, 4), sharey=True)
    for ax, load in zip(axes[:2], ("idle", "loaded"), strict=True):
        for phase in (p for p in phases if p["load"] == load):
            for client, style in (("skyhelm", "-"), ("mavsdk", ":")):
                errors = phase[client].get("abs_errors_ms") or []
                if not errors or (client == "mavsdk" and phase["variant"] != phases[0]["variant"]):
                    continue
                label = (f"SkyHelm 50 Hz ({phase['variant']})" if client == "skyhelm"
                         else "MAVSDK 20 Hz")
                ys = [1.0 - (i + 1) / len(errors) for i in range(len(errors))]
                ax.step([max(e, 1e-3) for e in errors], [max(y, 1e-4) for y in ys],
                        style, where="post", label=label)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"{load}" + (f": {result['load']['ws_clients']} WS clients at "
                                  f"{result['load']['telemetry_rate_hz']:g} Hz + "
                                  f"{result['load']['rest_reads_hz']:g} REST reads/s"
                                  if load == "loaded" else ": no clients"), fontsize=9)
        ax.set_xlabel("|interval − period| at the receiver (ms)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    options = result.get("sender_options") or []
    for row in options:
        errors = row.get("abs_errors_ms") or []
        if errors:
            ys = [1.0 - (i + 1) / len(errors) for i in range(len(errors))]
            axes[2].step([max(e, 1e-3) for e in errors], [max(y, 1e-4) for y in ys],
                         where="post", label=f"{row['option']}")
    axes[2].set_xscale("log")
    axes[2].set_yscale("log")
    axes[2].set_title("send paths, 50 Hz, one process's loop ~80% busy", fontsize=9)
    axes[2].set_xlabel("|interval − period| at the receiver (ms)")
    axes[2].grid(True, which="both", alpha=0.3)
    if options:
        axes[2].legend(fontsize=8)
    axes[0].set_ylabel("fraction of intervals above")
    fig.suptitle("Setpoint stream lateness, SkyHelm vs MAVSDK in the same run")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    figure = save_figure(fig, "stream_vs_mavsdk", "Stream lateness distribution (receiver side)",
                         machine)
    plt.close(fig)
    goal = result["goal"]
    rows = ["| variant | load | client | p50 \\|err\\| ms | p99 \\|err\\| ms | max interval ms "
            "| gaps > 100 ms | server CPU |", "|---|---|---|---|---|---|---|---|"]
    for phase in phases:
        for client in ("skyhelm", "mavsdk"):
            r = phase[client]
            rows.append(
                f"| {phase['variant']} | {phase['load']} | {client} {r['rate_hz']:g} Hz | "
                f"{r.get('abs_error_p50_ms', float('nan')):.2f} | "
                f"{r.get('abs_error_p99_ms', float('nan')):.2f} | "
                f"{r.get('interval_max_ms', float('nan')):.1f} | "
                f"{r.get('gaps_over_100ms', 0)} | "
                f"{phase['server_cpu_share_of_one_core'] * 100:.0f}% |")
    if options:
        rows += ["", "Send paths under synthetic load (one process, its loop ~80% busy "
                 "encoding JSON; 50 Hz):", "",
                 "| send path | p50 \\|err\\| ms | p99 \\|err\\| ms | max interval ms |",
                 "|---|---|---|---|"]
        rows += [f"| {r['option']} | {r.get('abs_error_p50_ms', float('nan')):.2f} | "
                 f"{r.get('abs_error_p99_ms', float('nan')):.2f} | "
                 f"{r.get('interval_max_ms', float('nan')):.1f} |" for r in options]
    ratio = goal.get("ratio_skyhelm_over_mavsdk")
    ratio_text = f"{ratio:.2g}" if ratio is not None else "n/a"
    markdown = (
        f"Under load, SkyHelm's 50 Hz stream ({goal['variant']} sender) has a p99 "
        f"|interval − period| of **{ratio_text}×** MAVSDK's 20 Hz offboard stream measured in "
        f"the same seconds at the same receiver (goal ≤ 1: "
        f"{'met' if goal['jitter_met'] else 'not met'}; no gap over 100 ms: "
        f"{'yes' if goal['no_gap_over_100ms'] else 'no'}).\n\n" + "\n".join(rows) + "\n"
    )
    return Section(title="Setpoint stream vs MAVSDK", order=10, markdown=markdown,
                   figures=[figure])


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=8.0, help="measuring time per phase")
    parser.add_argument("--quick", action="store_true", help="a 2 s smoke run per phase")
    parser.add_argument("--variants", default=",".join(DEFAULT_VARIANTS),
                        help=f"server send paths, from {','.join(VARIANTS)}")
    parser.add_argument("--load-url", help=argparse.SUPPRESS)
    parser.add_argument("--process-sender", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.process_sender:
        port, frame_hex, rate_hz, seconds = args.process_sender.split(":")
        process_sender(int(port), frame_hex, float(rate_hz), float(seconds))
        return 0
    if args.load_url:
        asyncio.run(load_worker(args.load_url, args.seconds))
        return 0
    variants = [v for v in args.variants.split(",") if v]
    unknown = set(variants) - set(VARIANTS)
    if unknown:
        parser.error(f"unknown variants: {', '.join(sorted(unknown))}")
    # importing it installs uvloop's loop policy: before the loop starts, not mid-run
    import mavsdk_grpc  # noqa: F401

    result = asyncio.run(run(2.0 if args.quick else args.seconds, variants))
    print_table(result)
    goal = result["goal"]
    print(f"\nloaded p99 |interval-period|: SkyHelm 50 Hz "
          f"{goal['skyhelm_50hz_loaded_p99_abs_error_ms']:.2f} ms vs MAVSDK 20 Hz "
          f"{goal['mavsdk_20hz_loaded_p99_abs_error_ms']:.2f} ms -> "
          f"{'met' if goal['jitter_met'] else 'NOT met'}; no gap > 100 ms: "
          f"{'yes' if goal['no_gap_over_100ms'] else 'NO'}")
    write_results("stream_vs_mavsdk", result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
