"""Cost of the 3D scene: per-vehicle update rate (target ≤ 30 Hz), time per batched tick,
the server process's CPU while one browser-like client watches through the proxy, and the
bytes that client receives.

Run: .venv/bin/python -m bench.scene_updates
Writes bench/results/scene_updates.json.
"""

from __future__ import annotations

import asyncio
import statistics
import time
from typing import Any

import viser
from fastapi import FastAPI
from websockets.asyncio.client import connect
from websockets.typing import Subprotocol

from bench._markdown import ratio, table
from bench._report import Section
from bench._results import machine_info, write_results
from server.link import VehicleState
from server.scene.hub import SceneHub
from tests.api.state_fakes import pushing, scene_fed_by
from tests.scene.conftest import FakeVehicle
from tests.serving import uvicorn_serving

TOKEN = "bench-scene-token"
MEASURE_S = 5.0
# How often each fake vehicle reports a change, as PX4's telemetry streams would.
TELEMETRY_RATE_HZ = 50.0


class _TimedHub(SceneHub):
    """The hub with each batched update timed."""

    def __init__(self) -> None:
        super().__init__(max_rate_hz=30.0)
        self.tick_s: list[float] = []

    def _apply_states(self, states: list[VehicleState], now_s: float) -> None:
        started = time.perf_counter()
        super()._apply_states(states, now_s)
        self.tick_s.append(time.perf_counter() - started)


async def _watch(hub: _TimedHub, host: str) -> tuple[int, float, float, int]:
    """Watch the scene like a browser for MEASURE_S: (updates applied, wall s, CPU s, bytes)."""
    received_bytes = 0
    async with connect(f"ws://{host}/scene",
                       subprotocols=[Subprotocol(f"viser-v{viser.__version__}")],
                       additional_headers={"Cookie": f"skyhelm_token={TOKEN}"},
                       max_size=None) as ws:
        await asyncio.wait_for(ws.recv(), 10.0)
        await asyncio.sleep(1.0)  # not a wait for an event: let the first full scene go out
        hub.tick_s.clear()
        applied0 = hub.updates_applied
        cpu0, wall0 = time.process_time(), time.perf_counter()
        while time.perf_counter() - wall0 < MEASURE_S:
            try:
                message = await asyncio.wait_for(ws.recv(), 0.2)
                received_bytes += len(message)
            except TimeoutError:
                pass
        wall = time.perf_counter() - wall0
        cpu = time.process_time() - cpu0
    return hub.updates_applied - applied0, wall, cpu, received_bytes


async def measure(vehicle_count: int) -> dict[str, Any]:
    vehicles = [pushing(FakeVehicle(i + 1)) for i in range(vehicle_count)]
    hub = _TimedHub()
    app = FastAPI()
    hub.mount(app, check_token=lambda t: t == TOKEN)
    async with (
        scene_fed_by(hub, vehicles, TELEMETRY_RATE_HZ),
        uvicorn_serving(app) as host,
    ):
        applied, wall, cpu, received_bytes = await _watch(hub, host)
    ticks_ms = sorted(t * 1000 for t in hub.tick_s)
    return {
        "vehicles": vehicle_count,
        "update_rate_per_vehicle_hz": round(applied / vehicle_count / wall, 1),
        "tick_p50_ms": round(statistics.median(ticks_ms), 2),
        "tick_p99_ms": round(ticks_ms[int(0.99 * (len(ticks_ms) - 1))], 2),
        "process_cpu_pct_of_one_core": round(100 * cpu / wall, 1),
        "client_kbytes_per_s": round(received_bytes / 1024 / wall, 1),
    }


async def run() -> list[dict[str, Any]]:
    return [await measure(n) for n in (1, 4)]


def main() -> int:
    rows = asyncio.run(run())
    for row in rows:
        print(
            f"{row['vehicles']} vehicle(s): {row['update_rate_per_vehicle_hz']} Hz per vehicle "
            f"(limit 30), tick p50 {row['tick_p50_ms']} ms / p99 {row['tick_p99_ms']} ms, "
            f"CPU {row['process_cpu_pct_of_one_core']}% of one core, "
            f"{row['client_kbytes_per_s']} kB/s to the client"
        )
    result = {"measure_s": MEASURE_S, "rows": rows, "machine": machine_info()}
    write_results("scene_updates", result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


def report(result: dict[str, Any]) -> Section | None:
    """Tick cost and CPU at 1 and at 4 vehicles."""
    rows = result["rows"]
    markdown = table(
        ["vehicles", "updates/s per vehicle (limit 30)", "tick p50 ms", "tick p99 ms",
         "server CPU % of one core", "kB/s to one client"],
        [[r["vehicles"], r["update_rate_per_vehicle_hz"], r["tick_p50_ms"], r["tick_p99_ms"],
          r["process_cpu_pct_of_one_core"], r["client_kbytes_per_s"]] for r in rows])
    if len(rows) >= 2:
        first, last = rows[0], rows[-1]
        markdown = (
            f"From {first['vehicles']} to {last['vehicles']} vehicles "
            f"({ratio(last['vehicles'], first['vehicles'])} the vehicles), the scene's CPU grows "
            f"{ratio(last['process_cpu_pct_of_one_core'], first['process_cpu_pct_of_one_core'])}"
            f" and its p99 tick {ratio(last['tick_p99_ms'], first['tick_p99_ms'])}; each "
            f"vehicle stays at ≤ 30 updates/s ({result['measure_s']:.0f} s per row, one "
            f"browser-like client).\n\n" + markdown)
    return Section("3D scene updates", 70, markdown)
