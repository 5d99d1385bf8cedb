"""Radio soak: one simulated vehicle (real time) hovering in OFFBOARD on SkyHelm's stream
through a lossy radio (tools.faultproxy), for a long time, and HEARTBEAT-only drops.

Set-up: `python -m sim` (one quad, real time), a FaultProxy in front of it with the loss
asked for (default 20 % each way, independent per datagram; `--burst N`: Gilbert–Elliott
bursts of mean N datagrams), and `skyhelm serve` (a subprocess) connected to the proxy's
server-facing port, streaming 50 Hz. A pilot script takes control, arms, takes off and
holds in OFFBOARD, then every `--command-every` seconds sends a command whose answer can
be checked against the vehicle's state: `mode OFFBOARD` (the state must say OFFBOARD),
`arm` (armed) and a parameter write (MIS_TAKEOFF_ALT, alternately 2.5 and 3.0, read back).
With `--heartbeat-drops N` the vehicle's HEARTBEATs alone are dropped N times for
`--drop-s` (3.6 s) each, 8 s apart, on a link without other faults.

Measured (printed, and written to bench/results/radio_soak.json):
- false link-lost verdicts: `connection` events with `connected: false` on a telemetry
  socket (there is no real cut, so every one is false); `link_quality` warnings;
- failsafes: the vehicle's own mode leaving OFFBOARD, read from its HEARTBEATs at the proxy
  (custom_mode), and the pilot's recoveries;
- commands: answered and true, answered 504 (no answer after the retries), and any other
  answer (503 link lost, 409, ...) or an ACCEPTED the vehicle's state disagrees with;
- setpoints: sent by the server (its stream statistics), reaching the proxy, and handed on
  to the vehicle (after the loss), with the largest gap at the vehicle.

    .venv/bin/python -m bench.radio_soak --minutes 30 --loss 20      # make soak
    .venv/bin/python -m bench.radio_soak --minutes 0 --heartbeat-drops 20
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import httpx
from websockets.asyncio.client import connect

from bench._results import machine_info, write_results
from bench.soak import TOKEN, percentile, sim_vehicles, skyhelm_serve
from tools.faultproxy import MAVLINK_MSG_ID_HEARTBEAT, FaultProxy, Faults

SET_POSITION_TARGET_LOCAL_NED = 84
MAVLINK2_STX = 0xFD
PX4_MAIN_MODE_OFFBOARD = 6  # custom_mode bits 16..23 (px4_custom_mode.h)
HOLD = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -5.0}
PARAM = "MIS_TAKEOFF_ALT"
DROP_SPACING_S = 8.0
STATE_POLL_S = 1.0


@dataclass
class Figures:
    started: float = field(default_factory=time.monotonic)
    setpoints_to_vehicle: list[float] = field(default_factory=list)
    setpoints_at_proxy: int = 0
    vehicle_modes: list[tuple[float, int]] = field(default_factory=list)  # changes only
    lost_events: list[dict[str, Any]] = field(default_factory=list)
    quality_events: list[dict[str, Any]] = field(default_factory=list)
    commands: dict[str, dict[str, int]] = field(default_factory=dict)
    wrong: list[str] = field(default_factory=list)
    recoveries: list[float] = field(default_factory=list)

    def now(self) -> float:
        return time.monotonic() - self.started

    def count(self, command: str, outcome: str) -> None:
        per = self.commands.setdefault(command, {})
        per[outcome] = per.get(outcome, 0) + 1


def tap(figures: Figures) -> Callable[[str, bytes], None]:
    def on_frame(direction: str, frame: bytes) -> None:
        if len(frame) < 10 or frame[0] != MAVLINK2_STX:
            return
        message_id = int.from_bytes(frame[7:10], "little")
        if direction == "to_vehicle" and message_id == SET_POSITION_TARGET_LOCAL_NED:
            figures.setpoints_to_vehicle.append(figures.now())
        elif (direction == "to_server" and message_id == MAVLINK_MSG_ID_HEARTBEAT
              and frame[5] == 1 and frame[6] == 1):  # the autopilot of system 1
            main_mode = frame[10 + 2]  # custom_mode (uint32, first field) byte 2
            if not figures.vehicle_modes or figures.vehicle_modes[-1][1] != main_mode:
                figures.vehicle_modes.append((figures.now(), main_mode))

    return on_frame


class Pilot:
    def __init__(self, client: httpx.AsyncClient, figures: Figures) -> None:
        self.client = client
        self.figures = figures
        self.lease: dict[str, str] = {}

    async def state(self) -> dict[str, Any]:
        response = await self.client.get("/api/v1/vehicles/1")
        response.raise_for_status()
        state: dict[str, Any] = response.json()
        return state

    async def wait(self, predicate: Callable[[dict[str, Any]], bool], timeout_s: float,
                   what: str) -> dict[str, Any]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with contextlib.suppress(httpx.HTTPError):
                state = await self.state()
                if predicate(state):
                    return state
            await asyncio.sleep(0.2)
        raise RuntimeError(f"{what} not within {timeout_s} s")

    async def post(self, path: str, body: Any = None) -> httpx.Response:
        return await self.client.post(f"/api/v1/vehicles/1/{path}", json=body,
                                      headers=self.lease)

    async def until_ok(self, path: str, body: Any = None) -> None:
        for _ in range(10):
            if (await self.post(path, body)).status_code == 200:
                return
        raise RuntimeError(f"{path} never answered 200")

    async def take_off(self) -> None:
        await self.wait(lambda s: s["global"] is not None and s["home"] is not None, 60.0,
                        "position and home")
        lease = await self.client.post("/api/v1/vehicles/1/control",
                                       json={"client_name": "radio-soak"})
        lease.raise_for_status()
        self.lease = {"X-Lease-Id": lease.json()["lease_id"]}
        await self.until_ok("arm")
        await self.until_ok("offboard/start", {"setpoint": HOLD})
        await self.wait(lambda s: s["position_ned"]["down_m"] < -4.0, 60.0, "climb")

    async def command(self, which: int) -> None:
        """One checked command; its outcome counted."""
        name, call, truth = self._command(which)
        try:
            response = await call()
        except httpx.HTTPError as exc:
            self.figures.count(name, f"error {type(exc).__name__}")
            return
        if response.status_code == 504:
            self.figures.count(name, "504")
            return
        if response.status_code != 200:
            self.figures.count(name, f"status {response.status_code}")
            self.figures.wrong.append(f"{name}: {response.status_code} {response.text[:200]}")
            return
        try:
            await self.wait(truth, 5.0, f"{name}'s effect")
        except RuntimeError as exc:
            self.figures.count(name, "answered but untrue")
            self.figures.wrong.append(str(exc))
            return
        self.figures.count(name, "answered and true")

    def _command(self, which: int) -> tuple[
        str, Callable[[], Any], Callable[[dict[str, Any]], bool]
    ]:
        kind = which % 3
        if kind == 0:
            return ("mode OFFBOARD", lambda: self.post("mode", {"mode": "OFFBOARD"}),
                    lambda s: s["mode"] == "OFFBOARD")
        if kind == 1:
            return "arm", lambda: self.post("arm"), lambda s: s["armed"] is True
        value = 2.5 if which % 2 else 3.0

        async def write() -> httpx.Response:
            return await self.client.put(f"/api/v1/vehicles/1/params/{PARAM}",
                                         json={"value": value}, headers=self.lease)

        return f"param write {PARAM}", write, lambda _s: True

    async def keep(self, stop: asyncio.Event, command_every_s: float) -> None:
        """Renew the lease, put the vehicle back into OFFBOARD when it left it (counted),
        and send a checked command every command_every_s."""
        next_command = time.monotonic() + command_every_s
        for which in itertools.count():
            while not stop.is_set() and time.monotonic() < next_command:
                with contextlib.suppress(httpx.HTTPError):
                    await self.client.put("/api/v1/vehicles/1/control", headers=self.lease)
                    state = await self.state()
                    if state["connected"] and state["mode"] not in ("OFFBOARD", "UNKNOWN"):
                        self.figures.recoveries.append(self.figures.now())
                        await self.post("offboard/start", {"setpoint": HOLD})
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), STATE_POLL_S)
            if stop.is_set():
                return
            await self.command(which)
            next_command += command_every_s


async def watch_events(url: str, figures: Figures, stop: asyncio.Event) -> None:
    async with connect(url, max_size=2**22) as ws:
        while not stop.is_set():
            try:
                message = json.loads(await asyncio.wait_for(ws.recv(), 1.0))
            except TimeoutError:
                continue
            if message.get("type") != "event":
                continue
            data = message.get("data", {})
            if message.get("kind") == "connection" and data.get("connected") is False:
                figures.lost_events.append({"t_s": round(figures.now(), 1), **data})
            elif message.get("kind") == "link_quality":
                figures.quality_events.append({"t_s": round(figures.now(), 1),
                                               "causes": data.get("causes")})


async def heartbeat_drops(proxy: FaultProxy, figures: Figures, count: int,
                          drop_s: float) -> list[dict[str, Any]]:
    """count drops of the vehicle's HEARTBEATs alone; per drop the verdicts during it."""
    runs = []
    for _ in range(count):
        lost_before = len(figures.lost_events)
        warned_before = len(figures.quality_events)
        filtered_before = proxy.counters()["to_server"].filtered
        proxy.drop_messages({MAVLINK_MSG_ID_HEARTBEAT}, drop_s, "to_server")
        await asyncio.sleep(DROP_SPACING_S)
        runs.append({
            "lost_verdicts": len(figures.lost_events) - lost_before,
            "warnings": [e["causes"] for e in figures.quality_events[warned_before:]],
            "heartbeats_dropped": proxy.counters()["to_server"].filtered - filtered_before,
        })
    return runs


async def run(args: argparse.Namespace) -> dict[str, Any]:
    load_before = os.getloadavg()
    figures = Figures()
    faults = Faults(loss_pct=args.loss, burst_frames=args.burst)
    async with (
        sim_vehicles(1) as (port,),
        FaultProxy(vehicle=("127.0.0.1", port), seed=args.seed) as proxy,
    ):
        proxy.add_tap(tap(figures))
        async with (
            skyhelm_serve([f"udpout:127.0.0.1:{proxy.server_facing_address[1]}"]) as (_, base),
            httpx.AsyncClient(base_url=base, timeout=30.0,
                              headers={"Authorization": f"Bearer {TOKEN}"}) as client,
        ):
            pilot = Pilot(client, figures)
            deadline = time.monotonic() + 60.0
            while not (await client.get("/api/v1/vehicles")).json():
                if time.monotonic() > deadline:
                    raise RuntimeError("the vehicle did not appear")
                await asyncio.sleep(0.5)
            await pilot.take_off()
            stop = asyncio.Event()
            ws_url = f"ws://{base.removeprefix('http://')}/api/v1/ws/telemetry?token={TOKEN}"
            watcher = asyncio.create_task(watch_events(ws_url, figures, stop))
            keeper = asyncio.create_task(pilot.keep(stop, args.command_every))
            await asyncio.sleep(2.0)
            print(f"[{figures.now():7.1f} s] hovering in OFFBOARD", flush=True)
            drops = await heartbeat_drops(proxy, figures, args.heartbeat_drops, args.drop_s)
            lost_before_soak = len(figures.lost_events)
            sent_before = (await client.get("/api/v1/vehicles/1/stream")).json()["sent"]
            at_proxy_before = proxy.counters()["to_vehicle"].in_
            to_vehicle_before = len(figures.setpoints_to_vehicle)
            soak_from = figures.now()
            proxy.configure(faults)
            print(f"[{soak_from:7.1f} s] soaking {args.minutes:g} min at {faults}", flush=True)
            await asyncio.sleep(args.minutes * 60.0)
            proxy.configure(Faults())
            sent = (await client.get("/api/v1/vehicles/1/stream")).json()["sent"] - sent_before
            stop.set()
            await asyncio.gather(watcher, keeper, return_exceptions=True)
            final = await pilot.state()
    arrivals = figures.setpoints_to_vehicle[to_vehicle_before:]
    gaps = [b - a for a, b in itertools.pairwise(arrivals)]
    first_offboard = next((t for t, m in figures.vehicle_modes
                           if m == PX4_MAIN_MODE_OFFBOARD), None)
    left_offboard = [(round(t, 1), m) for t, m in figures.vehicle_modes
                     if first_offboard is not None and t > first_offboard
                     and m != PX4_MAIN_MODE_OFFBOARD]
    return {
        "minutes": args.minutes, "loss_pct": args.loss, "burst_frames": args.burst,
        "heartbeat_drops": {"count": args.heartbeat_drops, "drop_s": args.drop_s,
                            "lost_verdicts": sum(r["lost_verdicts"] for r in drops),
                            "runs": drops},
        "false_lost_verdicts": len(figures.lost_events),
        "false_lost_verdicts_in_soak": len(figures.lost_events) - lost_before_soak,
        "lost_events": figures.lost_events,
        "link_quality_events": len(figures.quality_events),
        "vehicle_left_offboard": left_offboard,
        "operator_recoveries": [round(t, 1) for t in figures.recoveries],
        "commands": figures.commands,
        "wrong_answers": figures.wrong,
        "setpoints": {
            "sent_by_server": sent,
            "frames_into_proxy_to_vehicle": proxy.counters()["to_vehicle"].in_ - at_proxy_before,
            "to_vehicle": len(arrivals),
            "to_vehicle_share_of_sent": round(len(arrivals) / sent, 4) if sent else None,
            "vehicle_gap_p99_ms": _ms(percentile(gaps, 99)),
            "vehicle_max_gap_ms": _ms(max(gaps, default=None)),
        },
        "final_state": {key: final.get(key) for key in ("connected", "mode", "armed")}
        | {"link_quality": final.get("link_quality")},
        "proxy": proxy.stats(),
        "machine": machine_info(load_before),
    }


def _ms(seconds: float | None) -> float | None:
    return None if seconds is None else round(seconds * 1000.0, 1)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--loss", type=float, default=20.0, metavar="PCT")
    parser.add_argument("--burst", type=float, default=0.0, metavar="FRAMES")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--command-every", type=float, default=10.0, metavar="S")
    parser.add_argument("--heartbeat-drops", type=int, default=0, metavar="N")
    parser.add_argument("--drop-s", type=float, default=3.6, metavar="S")
    parser.add_argument("--name", default="radio_soak", help="bench/results/<name>.json")
    args = parser.parse_args()
    result = asyncio.run(run(args))
    summary = {key: result[key] for key in (
        "false_lost_verdicts", "vehicle_left_offboard", "operator_recoveries", "commands",
        "setpoints", "final_state")}
    summary["heartbeat_drop_lost_verdicts"] = result["heartbeat_drops"]["lost_verdicts"]
    print(json.dumps(summary, indent=1))
    write_results(args.name, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
