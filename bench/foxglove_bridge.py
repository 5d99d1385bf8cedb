"""What the Foxglove bridge costs at full rate: one simulated vehicle streaming all its
telemetry, a 20 Hz setpoint stream from `skyhelm serve`, and a Foxglove client subscribed
to every channel (the state at 50 Hz, every MAVLink message type, the setpoints sent,
pose, position, log), against the same server without the bridge, in one run.

Phases, each with a fresh server on the same simulated vehicle (bench._sim_tap, which
times every SET_POSITION_TARGET_LOCAL_NED with its datagram's kernel receive time):
``off`` (no --foxglove-port), ``direct`` (--foxglove-port, the client on the SDK's
loopback port) and ``proxied`` (the client through /api/v1/foxglove with the token, the
relay in the server's process), ROUNDS times in turn so that drift in the machine's load
falls on all of them. Per phase: the server's CPU share of one core (utime + stime of its
process, the SDK's threads included) and the stream's |interval − 50 ms| p99 at the
vehicle. The claims: the bridge costs ≤ 10 % of a core (direct − off) and leaves the
stream's p99 as it is (direct / off).

    .venv/bin/python -m bench.foxglove_bridge [--seconds 8] [--rounds 2] [--quick]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import socket
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import httpx
from websockets.asyncio.client import connect
from websockets.typing import Subprotocol

from bench._results import machine_info, write_results
from bench._serve import cpu_seconds, served
from bench.many_vehicles import TapProcess, stream_figures, take_control_and_stream

if TYPE_CHECKING:
    from bench._report import Section

TOKEN = "bench-token-0123456789"
STREAM_RATE_HZ = 20.0
STATE_RATE_HZ = 50.0
WARMUP_S = 2.0
PHASES = ("off", "direct", "proxied")
GOAL_CPU_SHARE = 0.10
# "does not change the p99": within this factor of the run without the bridge (or within
# GOAL_P99_SLACK_MS of it, where both are a fraction of a millisecond)
GOAL_P99_RATIO = 1.5
GOAL_P99_SLACK_MS = 0.5


@dataclass
class Subscriber:
    """A Foxglove client that subscribes to every channel as it is advertised."""

    messages: Counter[str] = field(default_factory=Counter)
    bytes: int = 0
    topics: dict[int, str] = field(default_factory=dict)

    def reset(self) -> None:
        self.messages.clear()
        self.bytes = 0

    async def run(self, url: str, subprotocol: str) -> None:
        async with connect(url, subprotocols=[Subprotocol(subprotocol)], max_size=None) as ws:
            subscriptions: dict[int, str] = {}
            async for frame in ws:
                if isinstance(frame, str):
                    message = json.loads(frame)
                    if message.get("op") != "advertise":
                        continue
                    new = []
                    for channel in message["channels"]:
                        subscription_id = len(subscriptions) + 1
                        subscriptions[subscription_id] = channel["topic"]
                        new.append({"id": subscription_id, "channelId": channel["id"]})
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                elif frame[0] == 1:  # message data: opcode, subscription id, time, payload
                    self.messages[subscriptions[int.from_bytes(frame[1:5], "little")]] += 1
                    self.bytes += len(frame)


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


async def measure_phase(tap: TapProcess, url: str, phase: str, seconds: float) -> dict[str, Any]:
    foxglove_port = _free_port()
    command = [
        sys.executable, "-m", "server.cli", "serve", "--port", "0", "--token", TOKEN,
        "--connect", url, "--rate-hz", str(STREAM_RATE_HZ), "--no-tlog", "--no-scene",
        "--telemetry-max-rate-hz", str(STATE_RATE_HZ), "--log-level", "warning",
        *([] if phase == "off" else ["--foxglove-port", str(foxglove_port)]),
    ]
    async with served(command) as (server, base):
        headers = {"Authorization": f"Bearer {TOKEN}"}
        async with httpx.AsyncClient(base_url=base, headers=headers, timeout=30) as client:
            for _ in range(300):
                if (await client.get("/api/v1/vehicles")).json():
                    break
                await asyncio.sleep(0.2)
            else:
                raise RuntimeError("the vehicle did not show within a minute")
            await take_control_and_stream(client, 1)
            subscriber = Subscriber()
            reader = None
            if phase == "direct":
                reader = asyncio.create_task(
                    subscriber.run(f"ws://127.0.0.1:{foxglove_port}", "foxglove.sdk.v1"))
            elif phase == "proxied":
                ws_base = base.replace("http://", "ws://")
                reader = asyncio.create_task(subscriber.run(
                    f"{ws_base}/api/v1/foxglove?token={TOKEN}", "foxglove.websocket.v1"))
            await asyncio.sleep(WARMUP_S)
            tap.say("reset")
            subscriber.reset()
            cpu0, wall0 = cpu_seconds(server.pid), time.monotonic()
            await asyncio.sleep(seconds)
            tap.say("report")
            wall_s = time.monotonic() - wall0
            cpu_share = (cpu_seconds(server.pid) - cpu0) / wall_s
            report = await tap.line()
            if reader is not None:
                reader.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await reader
                if reader.done() and not reader.cancelled() and reader.exception():
                    raise RuntimeError(f"the Foxglove client failed: {reader.exception()}")
    arrivals = report["arrivals"].get("1", [])
    return {
        "phase": phase,
        "seconds": round(wall_s, 2),
        "server_cpu_share_of_one_core": round(cpu_share, 4),
        "arrivals": arrivals,
        "channels": len(subscriber.messages),
        "messages_per_s": round(sum(subscriber.messages.values()) / wall_s, 1),
        "state_per_s": round(subscriber.messages.get("/vehicle_1/state", 0) / wall_s, 1),
        "kbytes_per_s": round(subscriber.bytes / wall_s / 1e3, 1),
    }


async def run(seconds: float, rounds: int) -> list[dict[str, Any]]:
    tap = await TapProcess.start(0, 1)
    try:
        ready = await tap.line()
        url = f"udpout:127.0.0.1:{ready['instances'][0]['api_local_port']}"
        return [await measure_phase(tap, url, phase, seconds)
                for _ in range(rounds) for phase in PHASES]
    finally:
        await tap.stop()


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    period_s = 1.0 / STREAM_RATE_HZ
    phases: dict[str, Any] = {}
    for phase in PHASES:
        mine = [r for r in runs if r["phase"] == phase]
        # intervals within each run only: a phase's runs are minutes apart
        errors = [stream_figures(r["arrivals"], period_s) for r in mine]
        cpu = sum(r["server_cpu_share_of_one_core"] * r["seconds"] for r in mine)
        wall = sum(r["seconds"] for r in mine)
        p99s = [e["p99_error_ms"] for e in errors if e["p99_error_ms"] is not None]
        phases[phase] = {
            "server_cpu_share_of_one_core": round(cpu / wall, 4),
            "stream_p99_error_ms": round(max(p99s), 3) if p99s else None,
            "stream_max_gap_ms": max((e["max_gap_ms"] or 0.0) for e in errors),
            "setpoints": sum(e["setpoints"] for e in errors),
            "channels": max(r["channels"] for r in mine),
            "messages_per_s": round(sum(r["messages_per_s"] for r in mine) / len(mine), 1),
            "state_per_s": round(sum(r["state_per_s"] for r in mine) / len(mine), 1),
            "kbytes_per_s": round(sum(r["kbytes_per_s"] for r in mine) / len(mine), 1),
        }
    off, direct = phases["off"], phases["direct"]
    cost = direct["server_cpu_share_of_one_core"] - off["server_cpu_share_of_one_core"]
    proxied_cost = (phases["proxied"]["server_cpu_share_of_one_core"]
                    - off["server_cpu_share_of_one_core"])
    p99_off, p99_on = off["stream_p99_error_ms"], direct["stream_p99_error_ms"]
    ratio = p99_on / p99_off if p99_off and p99_on is not None else None
    p99_kept = (p99_off is not None and p99_on is not None
                and (p99_on <= GOAL_P99_RATIO * p99_off or p99_on - p99_off <= GOAL_P99_SLACK_MS))
    return {
        "phases": phases,
        "bridge_cpu_share_of_one_core": round(cost, 4),
        "proxied_cpu_share_of_one_core": round(proxied_cost, 4),
        "stream_p99_ratio_with_over_without": round(ratio, 3) if ratio is not None else None,
        "goal_met": cost <= GOAL_CPU_SHARE and p99_kept,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=8.0, help="measured per phase")
    parser.add_argument("--rounds", type=int, default=2, help="times each phase runs")
    parser.add_argument("--quick", action="store_true", help="smoke run: one round of 3 s")
    args = parser.parse_args()
    seconds, rounds = (3.0, 1) if args.quick else (args.seconds, args.rounds)
    load_before = os.getloadavg()
    runs = asyncio.run(run(seconds, rounds))
    summary = summarise(runs)
    for phase, figures in summary["phases"].items():
        print(f"{phase:8s} server {100 * figures['server_cpu_share_of_one_core']:5.1f} % of a "
              f"core; stream p99 |interval − 50 ms| {figures['stream_p99_error_ms']} ms, max "
              f"gap {figures['stream_max_gap_ms']:.1f} ms; client: {figures['channels']} "
              f"channels, {figures['messages_per_s']} msg/s ({figures['state_per_s']} states/s), "
              f"{figures['kbytes_per_s']} kB/s", flush=True)
    print(f"bridge: {100 * summary['bridge_cpu_share_of_one_core']:.1f} % of a core (through "
          f"the proxy {100 * summary['proxied_cpu_share_of_one_core']:.1f} %); stream p99 "
          f"with/without {summary['stream_p99_ratio_with_over_without']}; "
          f"goal met: {summary['goal_met']}")
    write_results("foxglove_bridge", {
        "machine": machine_info(load_before),
        "stream_rate_hz": STREAM_RATE_HZ,
        "state_rate_hz": STATE_RATE_HZ,
        "seconds_per_phase": seconds,
        "rounds": rounds,
        "goal": {"cpu_share_of_one_core": GOAL_CPU_SHARE, "p99_ratio": GOAL_P99_RATIO,
                 "p99_slack_ms": GOAL_P99_SLACK_MS},
        **summary,
    })
    return 0


def report(result: dict[str, Any]) -> Section | None:
    from bench._markdown import table
    from bench._report import Section

    phases = result.get("phases")
    if not phases:
        return None
    names = {"off": "no bridge", "direct": "bridge, client on its port",
             "proxied": "bridge, client through /api/v1/foxglove"}
    rows = [
        [names[phase], f"{100 * f['server_cpu_share_of_one_core']:.1f} %",
         f"{f['stream_p99_error_ms']} ms", f"{f['stream_max_gap_ms']:.1f} ms",
         f"{f['channels']}", f"{f['messages_per_s']:.0f}", f"{f['state_per_s']:.0f}"]
        for phase, f in phases.items()
    ]
    markdown = (
        f"One simulated vehicle, a {result['stream_rate_hz']:g} Hz setpoint stream and a "
        f"Foxglove client subscribed to every channel (state at {result['state_rate_hz']:g} "
        f"Hz), {result['rounds']} × {result['seconds_per_phase']:g} s per phase: the bridge "
        f"costs {100 * result['bridge_cpu_share_of_one_core']:.1f} % of a core "
        f"({100 * result['proxied_cpu_share_of_one_core']:.1f} % with the client through the "
        f"proxy; goal ≤ {100 * result['goal']['cpu_share_of_one_core']:.0f} %), and the "
        f"stream's p99 with/without is {result['stream_p99_ratio_with_over_without']}.\n\n"
        + table(["server", "CPU (one core)", "stream p99 |interval − 50 ms|", "max gap",
                 "channels", "messages/s", "states/s"], rows))
    return Section("Foxglove bridge", 95, markdown)


if __name__ == "__main__":
    raise SystemExit(main())
