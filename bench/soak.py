"""Soak: SkyHelm flying 3 simulated vehicles for a long time through fault-injecting proxies.

Set-up: `python -m sim --count 3` (each vehicle on its own ephemeral UDP port), one
tools.faultproxy.FaultProxy in front of each, and `skyhelm serve` (a subprocess) connected
to the three proxies' server-facing ports. A script takes control of each vehicle, arms,
takes off and holds in OFFBOARD on a 50 Hz setpoint stream; 20 WebSocket telemetry clients
watch all three vehicles. Every `--fault-every` seconds (default 60) the proxies inject the
next fault, in turn: a loss burst (50% both ways, 10 s), a partition (5 s, both ways),
duplication (20%, 10 s), reordering (20%, 10 s), corruption (5% of datagrams, 10 s).
Whenever a vehicle is found out of OFFBOARD (its offboard-loss failsafe fired during a
partition) the script, as an operator would, starts OFFBOARD again; those are counted.

Measured (printed, and written to bench/results/soak.json):
- memory: the server process's RSS every 10 s; growth first to last sample and the slope
  of a least-squares line (MB per hour);
- file handles: /proc/<server pid>/fd count at the start and at the end;
- stream gaps at the receiving side: setpoint arrivals as the proxy hands them to each
  vehicle; intervals p50/p99 and the largest gap, split into clean time and fault windows
  (a fault's duration plus 5 s of recovery);
- lost telemetry: WebSocket state messages received per client and vehicle against
  rate × duration.

Not CI: 30 minutes by default. `bench/run_all.py` runs it only with SKYHELM_BENCH_SOAK=1.

    .venv/bin/python -m bench.soak [--minutes 30] [--fault-every 60]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import json
import math
import os
import statistics
import sys
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
from websockets.asyncio.client import connect

from bench._results import machine_info, write_results
from tools.faultproxy import FaultProxy, Faults

PROJECT_ROOT = Path(__file__).resolve().parent.parent
TOKEN = "soak-token-0123456789"
VEHICLES = 3
STREAM_RATE_HZ = 50.0
TELEMETRY_CLIENTS = 20
TELEMETRY_RATE_HZ = 5.0
SAMPLE_EVERY_S = 10.0
SUPERVISE_EVERY_S = 2.0
RECOVERY_S = 5.0  # after a fault window, still counted as the fault's
GAP_S = 3.0 / STREAM_RATE_HZ  # an interval longer than three periods is a gap
SET_POSITION_TARGET_LOCAL_NED = 84
MAVLINK2_STX = 0xFD
LAG_PROBE_S = 0.01
CLK_TCK = os.sysconf("SC_CLK_TCK")
HOLD_DOWN_M = -5.0


@dataclass(frozen=True)
class FaultKind:
    name: str
    faults: Faults | None  # None: a partition
    duration_s: float


FAULT_ROTATION = (
    FaultKind("loss burst 50%", Faults(loss_pct=50.0), 10.0),
    FaultKind("partition", None, 5.0),
    FaultKind("duplication 20%", Faults(duplicate_pct=20.0), 10.0),
    FaultKind("reordering 20%", Faults(reorder_pct=20.0), 10.0),
    FaultKind("corruption 5%", Faults(corrupt_pct=5.0), 10.0),
)


@dataclass
class Soak:
    started: float
    proxies: list[FaultProxy]
    arrivals: dict[int, list[float]] = field(default_factory=dict)  # sysid -> times
    windows: list[tuple[str, float, float]] = field(default_factory=list)  # name, start, end
    rss_kb: list[tuple[float, int]] = field(default_factory=list)
    recoveries: list[dict[str, Any]] = field(default_factory=list)
    # per client: (clean states, states during a fault or its recovery)
    telemetry: list[list[int]] = field(default_factory=list)
    telemetry_errors: list[str] = field(default_factory=list)
    # SkyHelm's "connection" events as the first telemetry client saw them
    link_events: list[dict[str, Any]] = field(default_factory=list)
    active: tuple[str, float] | None = None  # the fault being injected: name, start

    def now(self) -> float:
        return time.monotonic() - self.started

    def fault_at(self, t: float) -> str | None:
        """The fault whose window (its duration plus RECOVERY_S) covers ``t``, the latest
        one if two overlap."""
        if self.active is not None and t >= self.active[1]:
            return self.active[0]
        for name, start, end in reversed(self.windows):
            if start <= t <= end + RECOVERY_S:
                return name
        return None

    def clean_seconds(self, since: float, until: float) -> float:
        covered = 0.0
        for _, start, end in self.windows:
            covered += max(0.0, min(until, end + RECOVERY_S) - max(since, start))
        return until - since - covered


# -- processes -----------------------------------------------------------------------------


@contextlib.asynccontextmanager
async def sim_vehicles(count: int = VEHICLES) -> AsyncIterator[list[int]]:
    """`python -m sim --count 3` (real time) on ephemeral ports, answering whoever speaks
    first; the vehicles' API ports."""
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sim", "--count", str(count), "--api-port", "0",
        "--gcs-port", "0", "--api-local-port", "0", "--gcs-local-port", "0",
        "--ready-json", "--exit-on-stdin-eof",
        stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.DEVNULL, cwd=PROJECT_ROOT,
    )
    try:
        assert proc.stdout is not None
        ready = json.loads(await asyncio.wait_for(proc.stdout.readline(), 60.0))
        yield [inst["api_local_port"] for inst in ready["instances"]]
    finally:
        if proc.stdin is not None:
            proc.stdin.close()
        try:
            await asyncio.wait_for(proc.wait(), 20.0)
        except TimeoutError:
            proc.kill()
            await proc.wait()


@contextlib.asynccontextmanager
async def skyhelm_serve(links: list[str]) -> AsyncIterator[tuple[int, str]]:
    connects = [arg for url in links for arg in ("--connect", url)]
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "server.cli", "serve", "--port", "0", "--token", TOKEN,
        *connects, "--rate-hz", str(STREAM_RATE_HZ), "--no-scene", "--no-tlog",
        "--log-level", "warning", "--lease-ttl-s", "60",
        stdout=asyncio.subprocess.PIPE, cwd=PROJECT_ROOT,
    )
    try:
        assert proc.stdout is not None
        line = (await asyncio.wait_for(proc.stdout.readline(), 60.0)).decode()
        if not line.startswith("SkyHelm ready: "):
            raise RuntimeError(f"skyhelm serve did not start: {line!r}")
        yield proc.pid, line.split("SkyHelm ready: ")[1].split("/?token=")[0]
    finally:
        if proc.returncode is None:
            proc.send_signal(2)
            try:
                await asyncio.wait_for(proc.wait(), 20.0)
            except TimeoutError:
                proc.kill()
                await proc.wait()


def rss_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def open_fds(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK  # utime, stime


def runqueue_wait_s(pid: int) -> float:
    """Time the process's main thread (the server's event loop) waited for a core."""
    return int(Path(f"/proc/{pid}/schedstat").read_text().split()[1]) / 1e9


async def watch_own_loop(lags_s: list[float], stop: asyncio.Event) -> None:
    """How late this process's loop wakes: the arrival times the proxies record are late
    by as much, so a gap seen at every vehicle at once may be ours, not the server's."""
    loop = asyncio.get_running_loop()
    while not stop.is_set():
        due = loop.time() + LAG_PROBE_S
        await asyncio.sleep(LAG_PROBE_S)
        lags_s.append(loop.time() - due)


# -- flying --------------------------------------------------------------------------------


class Pilot:
    """Takes control of every vehicle, flies it into an OFFBOARD hover, keeps the leases and
    puts a vehicle back into OFFBOARD when it is found out of it."""

    def __init__(self, client: httpx.AsyncClient, soak: Soak) -> None:
        self.client = client
        self.soak = soak
        self.leases: dict[int, dict[str, str]] = {}

    async def state(self, sysid: int) -> dict[str, Any]:
        response = await self.client.get(f"/api/v1/vehicles/{sysid}")
        response.raise_for_status()
        state: dict[str, Any] = response.json()
        return state

    async def call(self, sysid: int, path: str, body: Any = None) -> httpx.Response:
        return await self.client.post(
            f"/api/v1/vehicles/{sysid}/{path}", json=body, headers=self.leases[sysid]
        )

    async def wait(self, sysid: int, predicate: Callable[[dict[str, Any]], bool],
                   timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate(await self.state(sysid)):
                return
            await asyncio.sleep(0.2)
        raise RuntimeError(f"vehicle {sysid}: {what} not within {timeout_s} s")

    async def take_off(self, sysid: int) -> None:
        await self.wait(sysid, lambda s: s["global"] is not None and s["home"] is not None,
                        60.0, "position and home")
        lease = await self.client.post(f"/api/v1/vehicles/{sysid}/control",
                                       json={"client_name": "soak"})
        lease.raise_for_status()
        self.leases[sysid] = {"X-Lease-Id": lease.json()["lease_id"]}
        await self.fly_offboard(sysid)

    async def fly_offboard(self, sysid: int) -> None:
        state = await self.state(sysid)
        if not state["armed"]:
            (await self.call(sysid, "arm")).raise_for_status()
            (await self.call(sysid, "takeoff", {"altitude_m": -HOLD_DOWN_M})).raise_for_status()
            await self.wait(sysid, lambda s: s["position_ned"]["down_m"] < HOLD_DOWN_M + 1.0,
                            60.0, "climb")
        hold = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": HOLD_DOWN_M}
        (await self.call(sysid, "offboard/start", {"setpoint": hold})).raise_for_status()

    async def supervise(self, stop: asyncio.Event) -> None:
        while not stop.is_set():
            for sysid in self.leases:
                try:
                    await self.client.put(f"/api/v1/vehicles/{sysid}/control",
                                          headers=self.leases[sysid])
                    state = await self.state(sysid)
                    if state["connected"] and state["mode"] != "OFFBOARD":
                        self.soak.recoveries.append({"t_s": round(self.soak.now(), 1),
                                                     "vehicle": sysid, "mode": state["mode"]})
                        await self.fly_offboard(sysid)
                except (httpx.HTTPError, RuntimeError, KeyError) as exc:
                    self.soak.recoveries.append({"t_s": round(self.soak.now(), 1),
                                                 "vehicle": sysid, "error": repr(exc)})
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), SUPERVISE_EVERY_S)


# -- load and faults -----------------------------------------------------------------------


async def telemetry_client(url: str, soak: Soak, counts: list[int], stop: asyncio.Event,
                           *, note_events: bool = False) -> None:
    try:
        async with connect(url, max_size=2**22) as ws:
            while not stop.is_set():
                try:
                    text = await asyncio.wait_for(ws.recv(), 1.0)
                except TimeoutError:
                    continue
                message = json.loads(text)
                if message.get("type") == "state":
                    counts[0 if soak.fault_at(soak.now()) is None else 1] += 1
                elif (note_events and message.get("type") == "event"
                      and message.get("kind") == "connection"):
                    now = soak.now()
                    soak.link_events.append({
                        "t_s": round(now, 1), "vehicle": message.get("vehicle"),
                        "connected": message["data"].get("connected"),
                        "during": soak.fault_at(now),
                    })
    except Exception as exc:  # a socket that fails is a finding, reported with the rest
        soak.telemetry_errors.append(repr(exc))


async def inject_faults(soak: Soak, every_s: float, until_s: float) -> None:
    index = 0
    next_at = every_s / 2
    while next_at + 1.0 < until_s:
        await asyncio.sleep(max(0.0, next_at - soak.now()))
        kind = FAULT_ROTATION[index % len(FAULT_ROTATION)]
        start = soak.now()
        soak.active = (kind.name, start)
        print(f"[{start:7.1f} s] fault: {kind.name} for {kind.duration_s:g} s", flush=True)
        for proxy in soak.proxies:
            if kind.faults is None:
                proxy.partition(kind.duration_s)
            else:
                proxy.configure(kind.faults)
        await asyncio.sleep(kind.duration_s)
        for proxy in soak.proxies:
            proxy.configure(Faults())
            proxy.heal()
        soak.windows.append((kind.name, start, soak.now()))
        soak.active = None
        index += 1
        next_at += every_s


async def sample_server(soak: Soak, pid: int, stop: asyncio.Event) -> None:
    while not stop.is_set():
        soak.rss_kb.append((soak.now(), rss_kb(pid)))
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), SAMPLE_EVERY_S)
    soak.rss_kb.append((soak.now(), rss_kb(pid)))


def tap_setpoints(soak: Soak, sysid: int) -> Callable[[str, bytes], None]:
    times = soak.arrivals.setdefault(sysid, [])

    def tap(direction: str, frame: bytes) -> None:
        if (direction == "to_vehicle" and len(frame) >= 10 and frame[0] == MAVLINK2_STX
                and int.from_bytes(frame[7:10], "little") == SET_POSITION_TARGET_LOCAL_NED):
            times.append(soak.now())

    return tap


# -- figures -------------------------------------------------------------------------------


def percentile(values: list[float], q: float) -> float | None:
    if not values:
        return None
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q / 100 * (len(ordered) - 1)))]


def slope_per_hour(samples: list[tuple[float, int]]) -> float | None:
    if len(samples) < 3:
        return None
    xs = [t for t, _ in samples]
    ys = [kb / 1024.0 for _, kb in samples]
    mean_x, mean_y = statistics.fmean(xs), statistics.fmean(ys)
    var = sum((x - mean_x) ** 2 for x in xs)
    cov = sum((x - mean_x) * (y - mean_y) for x, y in zip(xs, ys, strict=True))
    return cov / var * 3600.0 if var else None


def stream_figures(soak: Soak, measure_from: float) -> dict[str, Any]:
    per_vehicle: dict[str, Any] = {}
    for sysid, times in sorted(soak.arrivals.items()):
        clean: list[float] = []
        faulted: dict[str, list[float]] = {}
        for a, b in itertools.pairwise(times):
            if a < measure_from:
                continue
            window = soak.fault_at(a) or soak.fault_at(b)
            (faulted.setdefault(window, []) if window else clean).append(b - a)
        per_vehicle[str(sysid)] = {
            "setpoints": sum(1 for t in times if t >= measure_from),
            "clean_interval_p50_ms": _ms(percentile(clean, 50)),
            "clean_interval_p99_ms": _ms(percentile(clean, 99)),
            "clean_max_gap_ms": _ms(max(clean, default=None)),
            f"clean_gaps_over_{GAP_S * 1000:.0f}_ms": sum(1 for d in clean if d > GAP_S),
            "fault_max_gap_ms": {name: _ms(max(d)) for name, d in faulted.items()},
        }
    return per_vehicle


def _ms(seconds: float | None) -> float | None:
    return None if seconds is None else round(seconds * 1000.0, 1)


# -- main ----------------------------------------------------------------------------------


async def soak_run(minutes: float, fault_every_s: float) -> dict[str, Any]:
    load_before = os.getloadavg()
    started = time.monotonic()
    async with sim_vehicles() as ports:
        proxies = [FaultProxy(vehicle=("127.0.0.1", port), seed=index)
                   for index, port in enumerate(ports)]
        for proxy in proxies:
            await proxy.start()
        soak = Soak(started, proxies)
        try:
            links = [f"udpout:127.0.0.1:{p.server_facing_address[1]}" for p in proxies]
            async with (
                skyhelm_serve(links) as (pid, base),
                httpx.AsyncClient(base_url=base, timeout=30.0,
                                  headers={"Authorization": f"Bearer {TOKEN}"}) as client,
            ):
                return await _fly_and_measure(soak, pid, base, client, minutes, fault_every_s,
                                              load_before)
        finally:
            for proxy in proxies:
                await proxy.stop()


async def _fly_and_measure(soak: Soak, pid: int, base: str, client: httpx.AsyncClient,
                           minutes: float, fault_every_s: float,
                           load_before: tuple[float, float, float]) -> dict[str, Any]:
    deadline = time.monotonic() + 60.0
    while len((await client.get("/api/v1/vehicles")).json()) < VEHICLES:
        if time.monotonic() > deadline:
            raise RuntimeError("the vehicles did not all appear")
        await asyncio.sleep(0.5)
    pilot = Pilot(client, soak)
    await asyncio.gather(*(pilot.take_off(sysid) for sysid in range(1, VEHICLES + 1)))
    # the sysid of each proxy's vehicle: the i-th sim instance is sysid i + 1
    for index, proxy in enumerate(soak.proxies):
        proxy.add_tap(tap_setpoints(soak, index + 1))
    print(f"[{soak.now():7.1f} s] {VEHICLES} vehicles hovering in OFFBOARD at "
          f"{STREAM_RATE_HZ:g} Hz; soaking for {minutes:g} min", flush=True)

    stop = asyncio.Event()
    ws_url = (f"ws://{base.removeprefix('http://')}/api/v1/ws/telemetry?token={TOKEN}"
              f"&rate_hz={TELEMETRY_RATE_HZ:g}")
    soak.telemetry = [[0, 0] for _ in range(TELEMETRY_CLIENTS)]
    clients = [asyncio.create_task(telemetry_client(ws_url, soak, counts, stop,
                                                    note_events=index == 0))
               for index, counts in enumerate(soak.telemetry)]
    await asyncio.sleep(2.0)  # sockets up before counting starts
    for counts in soak.telemetry:
        counts[:] = [0, 0]
    measure_from = soak.now()
    fds_start = open_fds(pid)
    cpu_start, wait_start = cpu_seconds(pid), runqueue_wait_s(pid)
    lags_s: list[float] = []
    lag_watch = asyncio.create_task(watch_own_loop(lags_s, stop))
    sampler = asyncio.create_task(sample_server(soak, pid, stop))
    supervisor = asyncio.create_task(pilot.supervise(stop))
    duration_s = minutes * 60.0
    await inject_faults(soak, fault_every_s, measure_from + duration_s)
    await asyncio.sleep(max(0.0, measure_from + duration_s - soak.now()))
    measured_s = soak.now() - measure_from
    fds_end = open_fds(pid)
    cpu_s, wait_s = cpu_seconds(pid) - cpu_start, runqueue_wait_s(pid) - wait_start
    stop.set()
    await asyncio.gather(sampler, supervisor, lag_watch, *clients)
    server_stream = {}
    for sysid in range(1, VEHICLES + 1):
        stats = (await client.get(f"/api/v1/vehicles/{sysid}/stream")).json()
        server_stream[str(sysid)] = {
            key: round(stats[key], 1) if isinstance(stats.get(key), float) else stats.get(key)
            for key in ("sent", "interval_p50_ms", "interval_p99_ms", "max_gap_ms", "gaps")
        }

    expected = TELEMETRY_RATE_HZ * measured_s * VEHICLES
    clean_s = soak.clean_seconds(measure_from, measure_from + measured_s)
    expected_clean = TELEMETRY_RATE_HZ * clean_s * VEHICLES
    per_client = [sum(counts) / expected for counts in soak.telemetry]
    # (a run too short to have time outside its faults has no clean share)
    per_client_clean = [counts[0] / expected_clean for counts in soak.telemetry
                        if expected_clean >= 1.0] or [math.nan]
    rss = soak.rss_kb
    result: dict[str, Any] = {
        "minutes": round(measured_s / 60.0, 2),
        "vehicles": VEHICLES,
        "stream_rate_hz": STREAM_RATE_HZ,
        "telemetry_clients": TELEMETRY_CLIENTS,
        "telemetry_rate_hz": TELEMETRY_RATE_HZ,
        "faults": [{"kind": name, "start_s": round(start - measure_from, 1),
                    "end_s": round(end - measure_from, 1)} for name, start, end in soak.windows],
        "memory": {
            "rss_start_mb": round(rss[0][1] / 1024.0, 1),
            "rss_end_mb": round(rss[-1][1] / 1024.0, 1),
            "rss_max_mb": round(max(kb for _, kb in rss) / 1024.0, 1),
            "growth_mb": round((rss[-1][1] - rss[0][1]) / 1024.0, 1),
            "slope_mb_per_hour": _round(slope_per_hour(rss)),
            "samples": [[round(t - measure_from, 1), kb] for t, kb in rss],
        },
        "file_handles": {"start": fds_start, "end": fds_end},
        "stream_at_vehicles": stream_figures(soak, measure_from),
        # the streamer's own figures (recent window), to tell its gaps from the proxies'
        "stream_server_side": server_stream,
        "server_cpu_share": round(cpu_s / measured_s, 3),
        "server_loop_waited_for_core_s": round(wait_s, 2),
        "bench_loop_lag_ms": {"p99": _ms(percentile(lags_s, 99)),
                              "max": _ms(max(lags_s, default=None)),
                              "over_50_ms": sum(1 for lag in lags_s if lag > 0.05)},
        "telemetry": {
            "expected_per_client": round(expected),
            "received_share_mean": round(statistics.fmean(per_client), 4),
            "received_share_min": round(min(per_client), 4),
            # outside fault windows (+ RECOVERY_S), where every state should arrive
            "clean_seconds": round(clean_s, 1),
            "clean_expected_per_client": round(expected_clean),
            "clean_received_share_mean": round(statistics.fmean(per_client_clean), 4),
            "clean_received_share_min": round(min(per_client_clean), 4),
            "socket_errors": soak.telemetry_errors,
        },
        "operator_recoveries": soak.recoveries,
        "vehicle_lost": {
            "during_faults": sum(1 for e in soak.link_events
                                 if e["connected"] is False and e["during"] is not None),
            "outside_faults": sum(1 for e in soak.link_events
                                  if e["connected"] is False and e["during"] is None),
            "events": soak.link_events,
        },
        "proxies": [proxy.stats() for proxy in soak.proxies],
        "machine": machine_info(load_before),
    }
    return result


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 2)


def print_summary(result: dict[str, Any]) -> None:
    memory, fds, telemetry = result["memory"], result["file_handles"], result["telemetry"]
    print(f"\nsoak {result['minutes']} min, {result['vehicles']} vehicles at "
          f"{result['stream_rate_hz']:g} Hz, {result['telemetry_clients']} WS clients, "
          f"{len(result['faults'])} faults")
    print(f"server RSS {memory['rss_start_mb']} -> {memory['rss_end_mb']} MB "
          f"(max {memory['rss_max_mb']}, growth {memory['growth_mb']} MB, "
          f"slope {memory['slope_mb_per_hour']} MB/h); file handles {fds['start']} -> "
          f"{fds['end']}")
    for sysid, figures in result["stream_at_vehicles"].items():
        print(f"vehicle {sysid} (at the proxy): {figures}")
        print(f"vehicle {sysid} (server's streamer): {result['stream_server_side'][sysid]}")
    print(f"server CPU {100 * result['server_cpu_share']:.0f}% of a core, its loop waited "
          f"{result['server_loop_waited_for_core_s']} s for a core; bench loop lag "
          f"{result['bench_loop_lag_ms']}; load average {result['machine']['load_average_after']}")
    print(f"telemetry received {100 * telemetry['received_share_mean']:.1f}% of expected "
          f"(min client {100 * telemetry['received_share_min']:.1f}%); outside faults "
          f"{100 * telemetry['clean_received_share_mean']:.1f}% (min client "
          f"{100 * telemetry['clean_received_share_min']:.1f}%); socket errors "
          f"{len(telemetry['socket_errors'])}")
    lost = result["vehicle_lost"]
    print(f"vehicle marked lost by SkyHelm: {lost['during_faults']} times during a fault "
          f"window, {lost['outside_faults']} outside one")
    print(f"operator recoveries (back into OFFBOARD after a fault): "
          f"{len(result['operator_recoveries'])} {result['operator_recoveries']}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--fault-every", type=float, default=60.0, metavar="S")
    args = parser.parse_args()
    result = asyncio.run(soak_run(args.minutes, args.fault_every))
    print_summary(result)
    write_results("soak", result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
