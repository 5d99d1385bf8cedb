"""Screenshots of the dashboard in flight for docs/dashboard.md, taken in headless Chromium
against `skyhelm serve` with the simulated vehicle: the quad in offboard and the VTOL in
fixed-wing flight with the 3D scene (1600x1000); the quad flying to a point clicked on the
2D map at 1280x800, dark and light; and each panel on its own (map, instruments, sticks,
alerts, plots).

Run: .venv/bin/python -m bench.screenshots (also `make bench`)
Writes docs/img/dashboard-*.png, docs/img/panel-*.png and bench/results/screenshots.json
(how long each flight took to set up).
"""

from __future__ import annotations

import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench._results import write_results
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
WIDTH, HEIGHT = 1600, 1000
COCKPIT_SIZE = (1280, 800)
# Each panel's picture: docs/img/panel-<name>.png of the element the selector finds.
PANEL_SHOTS = {
    "map": ".views-panel",
    "instruments": ".panel:has(#instruments)",
    "sticks": "#sticks-panel",
    "plots": ".plots",
}
# Shot after another client takes control from the page (a real alert).
ALERT_SHOT = ("alerts", "#alerts")


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


def fly_by_map_click(page: Any, serve: Serve) -> None:
    """Takes off, then clicks a point 64 m north-east on the map and flies there."""
    import pymap3d

    with serve.client() as api:
        take_control(page)
        arm_and_take_off(page, api, 6.0)
        page.wait_for_selector(".map-vehicle", timeout=30_000)
        here = vehicle_state(api)["global"]
        lat, lon, _ = pymap3d.ned2geodetic(45.0, 45.0, 0.0, here["lat_deg"], here["lon_deg"], 0.0)
        point = page.evaluate("([a, b]) => window.skyhelm.map.pagePoint(a, b)", [lat, lon])
        page.mouse.click(point["x"], point["y"])
        page.fill("#map-goto-alt", "9")
        click_and_wait_result(page, "#map-goto-go")
        wait_for("the quad on its way", lambda: vehicle_state(api)["position_ned"]["north_m"] > 5,
                 30.0)


def shoot_panel(page: Any, name: str, selector: str) -> list[dict[str, Any]]:
    """docs/img/panel-<name>.png of the element, or nothing when it is not on the page."""
    element = page.locator(selector).first
    if element.count() == 0 or not element.is_visible():
        print(f"panel {name}: {selector} not on the page", file=sys.stderr)
        return []
    path = IMG_DIR / f"panel-{name}.png"
    element.screenshot(path=str(path))
    return [{"image": str(path.relative_to(ROOT)), "panel": name}]


def shoot_cockpit(browser: Any) -> list[dict[str, Any]]:
    """The page at 1280x800, map and no 3D scene, dark then light; then each panel."""
    serve = Serve(extra_args=["--sim-speed", "2", "--lease-ttl-s", "10"])
    started = time.monotonic()
    serve.start()
    shots: list[dict[str, Any]] = []
    # Playwright's string predicates run through eval, which the page's CSP forbids (the
    # policy itself is pinned by tests/browser/test_csp.py)
    context = browser.new_context(
        viewport={"width": COCKPIT_SIZE[0], "height": COCKPIT_SIZE[1]}, color_scheme="dark",
        bypass_csp=True,
    )
    try:
        page = open_dashboard(context, serve.url, scene=False)
        fly_by_map_click(page, serve)
        for scheme in ("dark", "light"):
            page.emulate_media(color_scheme=scheme)
            page.wait_for_timeout(300)
            path = IMG_DIR / f"dashboard-{COCKPIT_SIZE[0]}-{scheme}.png"
            page.screenshot(path=str(path))
            shots.append({"image": str(path.relative_to(ROOT)), "scheme": scheme})
        page.emulate_media(color_scheme="dark")
        for name, selector in PANEL_SHOTS.items():
            shots += shoot_panel(page, name, selector)
        with serve.client() as api:
            api.post("/vehicles/1/control",
                     json={"takeover": True, "force": True, "client_name": "ground crew"})
        page.wait_for_selector("#alerts .alert", timeout=15_000)
        shots += shoot_panel(page, *ALERT_SHOT)
    finally:
        context.close()
        serve.stop()
        serve.discard_log()
    seconds = time.monotonic() - started
    print(f"cockpit: {len(shots)} pictures after {seconds:.1f} s")
    for shot in shots:
        shot["wall_s"] = round(seconds, 1)
    return shots


def dismiss_scene_notifications(page: Any) -> None:
    """viser warns about software WebGL in a toast; it is noise in a screenshot. (Hidden, not
    clicked: clicks wait for frames that software WebGL delivers slowly.)"""
    toasts = page.frame_locator("#scene").locator(".mantine-Notification-root")
    toasts.evaluate_all("els => els.forEach(e => { e.style.display = 'none'; })")


def shoot(context: Any, airframe: str, fly: Callable[[Any, Serve], None]) -> dict[str, Any]:
    # A long lease: taking a screenshot of software-rendered WebGL can stall the page for
    # longer than the default 2 s, and the picture should show the pilot still in control.
    serve = Serve(extra_args=["--sim-airframe", airframe, "--sim-speed", "2",
                              "--lease-ttl-s", "10"])
    started = time.monotonic()
    serve.start()
    try:
        # Software WebGL is slow enough to stall clicks: fly first, then show the scene.
        page = open_dashboard(context, serve.url, scene=False)
        fly(page, serve)
        page.check("#scene-enable")
        page.frame_locator("#scene").locator("canvas").first.wait_for(timeout=30_000)
        page.wait_for_timeout(4000)
        dismiss_scene_notifications(page)
        page.wait_for_timeout(500)
        path = IMG_DIR / f"dashboard-{'quad' if airframe == 'quad' else airframe}.png"
        page.screenshot(path=str(path))
        page.close()
    finally:
        serve.stop()
        serve.discard_log()
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
            viewport={"width": WIDTH, "height": HEIGHT}, bypass_csp=True,
        )
        try:
            shots = [shoot(context, "quad", fly_quad), shoot(context, "vtol", fly_vtol)]
        finally:
            context.close()
        browser = playwright.chromium.launch(
            executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True
        )
        try:
            shots += shoot_cockpit(browser)
        finally:
            browser.close()
    write_results("screenshots", {"viewport": [WIDTH, HEIGHT], "screenshots": shots})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
