"""What the 2D map costs the page: headless Chromium at 1280x800 against `skyhelm serve`
with several simulated vehicles (the map draws every one), the 3D scene off. Measures, over
a window of flight-free telemetry, the time the page spends in the map's state handler per
state message, how many state messages the map handled per second, and the page's long
tasks (> 50 ms, the browser's own PerformanceObserver).

Run: .venv/bin/python -m bench.map_render [--vehicles 4] [--seconds 15]
Writes bench/results/map_render.json.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any

from bench._results import machine_info, write_results
from tests.browser.flows import open_dashboard
from tests.browser.harness import CHROMIUM, CHROMIUM_ARGS, Serve

# Wraps the map's state handler with a clock and counts the page's long tasks.
INSTRUMENT = """
() => {
  const map = window.skyhelm.map;
  const original = map.onState.bind(map);
  const costs = [];
  map.onState = (state) => {
    const t0 = performance.now();
    original(state);
    costs.push(performance.now() - t0);
  };
  const long = [];
  new PerformanceObserver((list) => { for (const e of list.getEntries()) long.push(e.duration); })
    .observe({ type: "longtask", buffered: false });
  window.__mapBench = { costs, long, started: performance.now() };
}
"""
COLLECT = """
() => {
  const b = window.__mapBench;
  return { costs: b.costs, long: b.long, elapsed_ms: performance.now() - b.started,
           drawn: document.querySelectorAll('.map-vehicle').length };
}
"""


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    if not ordered:
        return float("nan")
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


def measure(vehicles: int, seconds: float) -> dict[str, Any]:
    from playwright.sync_api import sync_playwright

    load_before = os.getloadavg()
    serve = Serve(extra_args=["--sim-count", str(vehicles)])
    serve.start()
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(
                executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True
            )
            context = browser.new_context(viewport={"width": 1280, "height": 800}, bypass_csp=True)
            page = open_dashboard(context, serve.url, scene=False)
            page.wait_for_function(
                f"document.querySelectorAll('.map-vehicle').length === {vehicles}",
                timeout=60_000,
            )
            page.evaluate(INSTRUMENT)
            time.sleep(seconds)  # not a wait: the measuring window
            found = page.evaluate(COLLECT)
            browser.close()
    finally:
        serve.stop()
        serve.discard_log()
    costs: list[float] = found["costs"]
    elapsed_s = found["elapsed_ms"] / 1000.0
    return {
        "vehicles": vehicles,
        "window_s": round(elapsed_s, 1),
        "vehicles_drawn": found["drawn"],
        "states_per_s": round(len(costs) / elapsed_s, 1),
        "on_state_ms": {
            "mean": round(sum(costs) / len(costs), 3) if costs else None,
            "p50": round(percentile(costs, 0.5), 3),
            "p99": round(percentile(costs, 0.99), 3),
            "max": round(max(costs), 3) if costs else None,
        },
        "map_busy_pct": round(100.0 * sum(costs) / found["elapsed_ms"], 2),
        "long_tasks": len(found["long"]),
        "longest_task_ms": round(max(found["long"]), 1) if found["long"] else 0.0,
        "machine": machine_info(load_before),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=15.0)
    args = parser.parse_args()
    if not CHROMIUM.exists():
        print("no /usr/bin/chromium: run `make chromium` as root", file=sys.stderr)
        return 1
    result = measure(args.vehicles, args.seconds)
    cost = result["on_state_ms"]
    print(f"map with {result['vehicles']} vehicles: {result['states_per_s']} states/s, "
          f"onState mean {cost['mean']} ms, p99 {cost['p99']} ms, max {cost['max']} ms; "
          f"map busy {result['map_busy_pct']} % of the page's time; "
          f"{result['long_tasks']} long tasks (longest {result['longest_task_ms']} ms)")
    write_results("map_render", result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
