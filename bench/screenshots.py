"""Screenshots of the dashboard in flight (quad in offboard, VTOL in fixed-wing flight) for
docs/img/, taken in headless Chromium against `skyhelm serve` with the simulated vehicle.

Run: .venv/bin/python -m bench.screenshots
Writes docs/img/dashboard-quad.png, docs/img/dashboard-vtol.png and
bench/results/screenshots.json (how long each flight took to set up).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tests.browser.flows import (
    arm_and_take_off,
    click_and_wait_result,
    drag_slider_to,
    open_dashboard,
    take_control,
)
from tests.browser.harness import CHROMIUM, CHROMIUM_ARGS, Serve, vehicle_state, wait_for

ROOT = Path(__file__).resolve().parents[1]
IMG_DIR = ROOT / "docs" / "img"
RESULTS = ROOT / "bench" / "results" / "screenshots.json"
WIDTH, HEIGHT = 1600, 1000


def fly_quad(page: Any, serve: Serve) -> None:
    with serve.client() as api:
        take_control(page)
        arm_and_take_off(page, api, 6.0)
        page.select_option("#sp-type", "position")
        page.click("#sp-from-here")
        click_and_wait_result(page, "#btn-offboard-start")
        drag_slider_to(page, "#sp-north_m-slider", 12.0)
        drag_slider_to(page, "#sp-alt_m-slider", 10.0)
        wait_for("the quad on its way", lambda: vehicle_state(api)["position_ned"]["north_m"] > 6,
                 30.0)


def fly_vtol(page: Any, serve: Serve) -> None:
    with serve.client() as api:
        take_control(page)
        arm_and_take_off(page, api, 20.0)
        click_and_wait_result(page, "#btn-to-fw")
        wait_for("fixed-wing flight", lambda: vehicle_state(api)["vtol_state"] == "FW", 30.0)
        time.sleep(4.0)


def shoot(context: Any, airframe: str, fly: Callable[[Any, Serve], None]) -> dict[str, Any]:
    serve = Serve(extra_args=["--sim-airframe", airframe, "--sim-speed", "2"])
    started = time.monotonic()
    serve.start()
    try:
        page = open_dashboard(context, serve.url)
        fly(page, serve)
        page.wait_for_timeout(1500)
        path = IMG_DIR / f"dashboard-{'quad' if airframe == 'quad' else airframe}.png"
        page.screenshot(path=str(path))
        page.close()
    finally:
        serve.stop()
    seconds = time.monotonic() - started
    print(f"{airframe}: {path.relative_to(ROOT)} after {seconds:.1f} s")
    return {"airframe": airframe, "image": str(path.relative_to(ROOT)), "wall_s": round(seconds, 1)}


def main() -> int:
    if not CHROMIUM.exists():
        print("no /usr/bin/chromium: run `make chromium` as root", file=sys.stderr)
        return 1
    from playwright.sync_api import sync_playwright

    IMG_DIR.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="skyhelm-chromium-") as profile, \
            sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            profile, executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True,
            viewport={"width": WIDTH, "height": HEIGHT},
        )
        try:
            shots = [shoot(context, "quad", fly_quad), shoot(context, "vtol", fly_vtol)]
        finally:
            context.close()
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    summary = {"viewport": [WIDTH, HEIGHT], "screenshots": shots}
    RESULTS.write_text(json.dumps(summary, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
