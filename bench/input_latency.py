"""A key or a stick from the page → the changed setpoint at the vehicle's socket.

`skyhelm serve` links to the simulated vehicle (real time, its own process) through a relay
that takes the kernel's receive time (SO_TIMESTAMPNS) of every datagram the server sends,
as the vehicle is about to receive it. A pilot presses and releases, as the page does:

- ``ws velocity``: a held key over the control socket: the ``velocity`` intent (body frame),
  repeated every 100 ms while held; released: the ``brake`` intent (a zero velocity first);
- ``ws sticks``: sticks over the control socket at 25 Hz, pitch full forward while held,
  centred when released;
- ``rest setpoint``: ``PUT /setpoint?live=true``, a velocity every 100 ms while held, a zero
  velocity when released;
- ``rest sticks``: ``PUT /sticks`` at 25 Hz, as over the socket.

Each figure is the input's send time (the client's clock, Unix time as the kernel's) to
the first frame at the vehicle's socket carrying the change (SET_POSITION_TARGET_LOCAL_NED
with a velocity / zero velocity, MANUAL_CONTROL with x = 1000 / 0). Goal: p99 ≤ 20 ms, press
and release. The streams run at their rates: 20 Hz setpoints, 25 Hz sticks. One press before
the counted ones starts each stream (and the server's sender process).

``--before REF`` runs the same cases first against the server of a git commit (exported
with ``git archive`` to a temporary directory), so both figures come from one run.

    .venv/bin/python -m bench.input_latency [--presses 20] [--before REF] [--quick]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import io
import json
import os
import struct
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import httpx
from websockets.asyncio.client import ClientConnection, connect

from bench._markdown import table
from bench._report import Section
from bench._results import machine_info, write_results
from bench._serve import PROJECT_ROOT, percentile, served
from server.simproc import SimProcess
from tests.faults.sender_relay import Heard, SenderRelay

TOKEN = "bench-input-latency-token"
SETPOINT_ID = 84  # SET_POSITION_TARGET_LOCAL_NED
STICKS_ID = 69  # MANUAL_CONTROL
HOLD_S = 0.30
BETWEEN_S = 0.30
KEY_REPEAT_S = 0.10  # the page's key repeat (web/offboard.js)
# a sample slower than the goal (20 ms) whose REST answer came later too: the server's
# request path was slow (the loop, the machine), not the sender's
SLOW_S = 0.020
STICKS_PERIOD_S = 0.04  # the page's sticks (web/sticks.js, 25 Hz)
SPEED_M_S = 1.0
# where each case's frames are found, and whether a frame carries the pressed input
CASES = ("ws velocity", "ws sticks", "rest setpoint", "rest sticks")
_SERVE = "import sys; from server.cli import main; raise SystemExit(main(sys.argv[1:]))"


def _setpoint_moving(heard: Heard) -> bool:
    # time_boot_ms, x, y, z, then vx, vy, vz (MAVLink 2 trims trailing zeros)
    payload = heard.payload.ljust(53, b"\0")
    vx, vy, vz = struct.unpack_from("<3f", payload, 16)
    return bool(abs(vx) + abs(vy) + abs(vz) > 1e-3)


def _sticks_pressed(heard: Heard) -> bool:
    (x,) = struct.unpack_from("<h", heard.payload.ljust(11, b"\0"), 0)
    return bool(x != 0)


def _first(relay: SenderRelay, msg_id: int, since_s: float, pressed: bool) -> float | None:
    moving = _sticks_pressed if msg_id == STICKS_ID else _setpoint_moving
    for heard in relay.since(since_s, msg_id):
        if moving(heard) == pressed:
            return heard.unix_s
    return None


@contextlib.asynccontextmanager
async def _server(root: Path, relay_port: int) -> AsyncIterator[str]:
    """`skyhelm serve` of the tree at ``root`` linked to the relay; yields its base URL."""
    command = [
        sys.executable, "-c", _SERVE, "serve", "--port", "0", "--token", TOKEN,
        "--connect", f"udpout:127.0.0.1:{relay_port}", "--no-scene", "--no-tlog",
        "--no-access-log", "--log-level", "warning",
    ]
    async with served(command, env={"PYTHONPATH": str(root)}, cwd=root) as (_proc, url):
        yield url


async def _vehicle_seen(client: httpx.AsyncClient) -> None:
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        response = await client.get("/api/v1/vehicles")
        if response.status_code == 200 and response.json():
            state = (await client.get("/api/v1/vehicles/1")).json()
            if state.get("position_ned") is not None:
                return
        await asyncio.sleep(0.2)
    raise RuntimeError("the vehicle never showed a position")


class _Socket:
    """The page's control socket: sends, and reads (and drops) the answers meanwhile."""

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws
        self.ids = 0
        self.answered = 0
        self._answers = asyncio.Condition()
        self._reader = asyncio.create_task(self._read())

    async def _read(self) -> None:
        async for text in self.ws:
            answer_id = json.loads(text).get("id")
            if isinstance(answer_id, int):
                async with self._answers:
                    self.answered = max(self.answered, answer_id)
                    self._answers.notify_all()

    async def send(self, message: dict[str, Any]) -> float:
        self.ids += 1
        text = json.dumps({**message, "id": self.ids})
        sent_s = time.time()
        await self.ws.send(text)
        return sent_s

    async def close(self) -> None:
        """Once every message was answered (or 5 s passed): the server is not left
        answering a closed socket."""
        async with self._answers:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(
                    self._answers.wait_for(lambda: self.answered >= self.ids), 5.0)
        self._reader.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._reader


def _velocity_command(forward_m_s: float) -> dict[str, Any]:
    return {"type": "command", "name": "velocity",
            "args": {"frame": "body", "forward_m_s": forward_m_s, "right_m_s": 0.0,
                     "up_m_s": 0.0, "yaw_rate_deg_s": 0.0}}


def _sticks(pitch: float) -> dict[str, float]:
    return {"pitch": pitch, "roll": 0.0, "yaw": 0.0, "throttle": 0.5}


async def _presses(
    relay: SenderRelay, msg_id: int, presses: int,
    press: Callable[[], Awaitable[float]], hold: Callable[[], Awaitable[None]],
    release: Callable[[], Awaitable[float]], between: Callable[[], Awaitable[None]],
    answers: dict[float, float] | None = None,
) -> dict[str, list[float]]:
    """Press, hold, release, wait, ``presses`` times after one press not counted (the
    first of a stream starts the server's sender process); latencies in ms. ``answers``
    (REST): each request's answer time by its send time, so a slow sample tells whether
    the server's request path was slow too (the answer after the frame's usual time)."""
    out: dict[str, list[float]] = {"press_ms": [], "release_ms": [], "missed": [],
                                   "slow_answered_late": []}
    for n in range(presses + 1):
        await between()
        pressed_s = await press()
        await hold()
        released_s = await release()
        await between()
        if n == 0:
            continue
        for key, since_s, pressed in (("press_ms", pressed_s, True),
                                      ("release_ms", released_s, False)):
            arrived = _first(relay, msg_id, since_s, pressed)
            if arrived is None:
                out["missed"].append(since_s)
            else:
                out[key].append((arrived - since_s) * 1e3)
                answered_s = (answers or {}).get(since_s)
                if (arrived - since_s > SLOW_S and answered_s is not None
                        and answered_s - since_s > SLOW_S):
                    out["slow_answered_late"].append(since_s)
    return out


async def _repeat(every_s: float, send: Callable[[], Awaitable[Any]], for_s: float) -> None:
    end = time.monotonic() + for_s
    while True:
        await asyncio.sleep(min(every_s, max(0.0, end - time.monotonic())))
        if time.monotonic() >= end:
            return
        await send()


async def _ws_cases(base: str, relay: SenderRelay, presses: int) -> dict[str, Any]:
    url = base.replace("http://", "ws://") + f"/api/v1/ws/control?vehicle=1&token={TOKEN}"
    results: dict[str, Any] = {}
    async with connect(url) as ws:
        json.loads(await ws.recv())  # the lease
        sock = _Socket(ws)
        try:
            # keys: the velocity intent repeated while held, brake on release
            forward = _velocity_command(SPEED_M_S)
            results["ws velocity"] = await _presses(
                relay, SETPOINT_ID, presses,
                press=lambda: sock.send(forward),
                hold=lambda: _repeat(KEY_REPEAT_S, lambda: sock.send(forward), HOLD_S),
                release=lambda: sock.send({"type": "command", "name": "brake", "args": {}}),
                between=lambda: asyncio.sleep(BETWEEN_S))
            # sticks: 25 Hz all along; full forward while held
            results["ws sticks"] = await _presses(
                relay, STICKS_ID, presses,
                press=lambda: sock.send({"type": "sticks", "sticks": _sticks(1.0)}),
                hold=lambda: _repeat(STICKS_PERIOD_S, lambda: sock.send(
                    {"type": "sticks", "sticks": _sticks(1.0)}), HOLD_S),
                release=lambda: sock.send({"type": "sticks", "sticks": _sticks(0.0)}),
                between=lambda: _repeat(STICKS_PERIOD_S, lambda: sock.send(
                    {"type": "sticks", "sticks": _sticks(0.0)}), BETWEEN_S))
            await sock.send({"type": "sticks", "stop": True})
        finally:
            await sock.close()
    return results


async def _rest_cases(base: str, relay: SenderRelay, presses: int) -> dict[str, Any]:
    results: dict[str, Any] = {}
    async with httpx.AsyncClient(base_url=base, timeout=10.0,
                                 headers={"Authorization": f"Bearer {TOKEN}"}) as client:
        lease = await client.post("/api/v1/vehicles/1/control", json={"ttl_s": 60.0})
        lease.raise_for_status()
        headers = {"X-Lease-Id": lease.json()["lease_id"]}

        answers: dict[float, float] = {}

        async def put(path: str, body: dict[str, Any]) -> float:
            sent_s = time.time()
            response = await client.put(f"/api/v1/vehicles/1/{path}", json=body,
                                        headers=headers)
            answers[sent_s] = time.time()
            response.raise_for_status()
            return sent_s

        def velocity(north_m_s: float) -> dict[str, Any]:
            return {"type": "velocity_ned", "north_m_s": north_m_s, "east_m_s": 0.0,
                    "down_m_s": 0.0}

        results["rest setpoint"] = await _presses(
            relay, SETPOINT_ID, presses,
            press=lambda: put("setpoint?live=true", velocity(SPEED_M_S)),
            hold=lambda: _repeat(KEY_REPEAT_S,
                                 lambda: put("setpoint?live=true", velocity(SPEED_M_S)), HOLD_S),
            release=lambda: put("setpoint?live=true", velocity(0.0)),
            between=lambda: _repeat(KEY_REPEAT_S,
                                    lambda: put("setpoint?live=true", velocity(0.0)), BETWEEN_S),
            answers=answers)
        results["rest sticks"] = await _presses(
            relay, STICKS_ID, presses,
            press=lambda: put("sticks", _sticks(1.0)),
            hold=lambda: _repeat(STICKS_PERIOD_S, lambda: put("sticks", _sticks(1.0)), HOLD_S),
            release=lambda: put("sticks", _sticks(0.0)),
            between=lambda: _repeat(STICKS_PERIOD_S, lambda: put("sticks", _sticks(0.0)),
                                    BETWEEN_S),
            answers=answers)
        await client.delete("/api/v1/vehicles/1/sticks", headers=headers)
        await client.delete("/api/v1/vehicles/1/control", headers=headers)
    return results


def _summary(values_ms: list[float]) -> dict[str, float | int | None]:
    return {"count": len(values_ms), "p50_ms": percentile(values_ms, 50),
            "p99_ms": percentile(values_ms, 99),
            "max_ms": max(values_ms) if values_ms else None}


async def measure(root: Path, presses: int) -> dict[str, Any]:
    """Every case against the server of the tree at ``root``."""
    sim = SimProcess()  # its own process, as `skyhelm serve` runs it: not this one's loop
    instances = await sim.start()
    try:
        relay = SenderRelay(("127.0.0.1", instances[0].api_local_port))
        try:
            async with _server(root, relay.port) as base:
                async with httpx.AsyncClient(
                        base_url=base, headers={"Authorization": f"Bearer {TOKEN}"}) as client:
                    await _vehicle_seen(client)
                raw = await _ws_cases(base, relay, presses)
                raw.update(await _rest_cases(base, relay, presses))
        finally:
            relay.close()
    finally:
        await sim.stop()
    return {case: {"press": _summary(raw[case]["press_ms"]),
                   "release": _summary(raw[case]["release_ms"]),
                   "missed": len(raw[case]["missed"]),
                   # samples over SLOW_S whose REST answer also came after SLOW_S
                   "slow_answered_late": len(raw[case]["slow_answered_late"]),
                   "samples_ms": {"press": raw[case]["press_ms"],
                                  "release": raw[case]["release_ms"]}}
            for case in CASES}


@contextlib.contextmanager
def _exported(ref: str) -> Any:
    """The tree of git commit ``ref``, in a temporary directory."""
    archive = subprocess.run(["git", "archive", "--format=tar", ref, "server", "sim", "bench"],
                             cwd=PROJECT_ROOT, check=True, capture_output=True).stdout
    with tempfile.TemporaryDirectory(prefix="skyhelm-before-") as tmp:
        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            tar.extractall(tmp, filter="data")
        yield Path(tmp)


def _short_commit(ref: str) -> str:
    return subprocess.run(["git", "rev-parse", "--short", ref], cwd=PROJECT_ROOT, check=True,
                          capture_output=True, text=True).stdout.strip()


def _print(label: str, figures: dict[str, Any]) -> None:
    for case in CASES:
        row = figures[case]
        parts = []
        for edge in ("press", "release"):
            s = row[edge]
            if s["count"]:
                parts.append(f"{edge} p50 {s['p50_ms']:5.1f} p99 {s['p99_ms']:5.1f} "
                             f"max {s['max_ms']:5.1f} ms")
            else:
                parts.append(f"{edge} -")
        missed = f", missed {row['missed']}" if row["missed"] else ""
        if row.get("slow_answered_late"):
            missed += (f", {row['slow_answered_late']} over {SLOW_S * 1e3:.0f} ms answered "
                       f"later than that too")
        print(f"{label:>6} {case:<14} {' | '.join(parts)}  (n={row['press']['count']}{missed})")


async def run(presses: int, before: str | None) -> dict[str, Any]:
    load_before = os.getloadavg()
    result: dict[str, Any] = {"presses": presses, "hold_s": HOLD_S, "between_s": BETWEEN_S}
    if before is not None:
        commit = await asyncio.to_thread(_short_commit, before)
        with _exported(before) as root:
            result["before"] = {"commit": commit, **await measure(root, presses)}
        _print("before", result["before"])
    result["after"] = await measure(PROJECT_ROOT, presses)
    _print("after", result["after"])
    worst = [result["after"][c][e]["p99_ms"] for c in CASES for e in ("press", "release")]
    result["worst_p99_ms"] = max(w for w in worst if w is not None)
    result["machine"] = machine_info(load_before)
    return result


def _cell(summary: dict[str, Any]) -> str:
    if not summary["count"]:
        return "–"
    return f"{summary['p50_ms']:.1f} / {summary['p99_ms']:.1f} / {summary['max_ms']:.1f}"


def report(result: dict[str, Any]) -> Section | None:
    """Press and release latency per input path, before and after when both were run."""
    after = result.get("after")
    if not after:
        return None
    before = result.get("before")
    rows = []
    for case in CASES:
        for edge in ("press", "release"):
            row = [f"{case}, {edge}"]
            if before:
                row.append(_cell(before[case][edge]))
            row.append(_cell(after[case][edge]))
            rows.append(row)
    headers = ["input", *([f"before ({before['commit']}) p50 / p99 / max ms"] if before else []),
               "p50 / p99 / max ms"]
    worst = result["worst_p99_ms"]
    markdown = (
        f"A key or a stick, given as the page gives it (control socket) or over REST, to the "
        f"first frame carrying the change at the vehicle's socket (kernel receive times at a "
        f"relay), {result['presses']} presses and releases per path: worst p99 "
        f"**{worst:.1f} ms** (goal ≤ 20 ms: {'met' if worst <= 20.0 else 'NOT met'}).\n\n"
        + table(headers, rows)
    )
    late = [(label, sum(figures[case].get("slow_answered_late", 0) for case in CASES))
            for label, figures in (("before", before), ("after", after)) if figures]
    if any(count for _, count in late):
        markdown += (
            f"\n\nSamples over {SLOW_S * 1e3:.0f} ms whose REST answer came later than that "
            "too (the server's request path was slow: the loop, the machine; not the "
            "stream): " + ", ".join(f"{label} {count}" for label, count in late) + ".\n")
    return Section("A key or a stick to the vehicle", 45, markdown)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presses", type=int, default=20)
    parser.add_argument("--quick", action="store_true", help="5 presses: a smoke run")
    parser.add_argument("--before", metavar="REF",
                        help="also measure the server of this git commit first")
    args = parser.parse_args()
    presses = 5 if args.quick else args.presses
    write_results("input_latency", asyncio.run(run(presses, args.before)))


if __name__ == "__main__":
    main()
