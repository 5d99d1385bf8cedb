"""Screenshots of the dashboard in flight for docs/dashboard.md, taken in headless Chromium
against `skyhelm serve` with the simulated vehicle: the quad in offboard and the VTOL in
fixed-wing flight with the 3D scene (1600x1000); then the cockpit's states as the layout
probe walks them (tests/browser/cockpit_walk.py: in control, a takeover request, offboard,
the link lost, a failsafe, sticks, a VTOL in fixed-wing flight) at 1024x768, 1280x800 and
1920x1080, dark and light, and each panel on its own (map, instruments, sticks, alerts,
plots). The walk also runs its probe: a picture is written only of a layout it checked.

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
from tests.browser.cockpit_walk import (
    QUAD_SERVE_ARGS,
    VTOL_SERVE_ARGS,
    Shot,
    Walk,
    walk_quad,
    walk_vtol,
)
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
# The pictures taken in the walk's states (docs/img/<name>.png).
QUAD_SHOTS = {
    "in control": [Shot("dashboard-1024", size=(1024, 768))],
    "takeover request": [Shot("dashboard-takeover")],
    "flying offboard": [
        Shot("dashboard-1280-dark"),
        Shot("dashboard-1280-light", scheme="light"),
        Shot("dashboard-1920", size=(1920, 1080)),
        Shot("panel-map", selector=".views-panel"),
        Shot("panel-instruments", selector=".panel:has(#instruments)"),
        Shot("panel-plots", selector=".plots"),
    ],
    "link lost": [Shot("dashboard-link-lost"), Shot("panel-alerts", selector="#alerts")],
    "failsafe": [Shot("dashboard-failsafe", scheme="light")],
    "sticks": [Shot("panel-sticks", selector="#sticks-panel")],
}
VTOL_SHOTS = {"VTOL in fixed-wing flight": [Shot("dashboard-vtol-fixed-wing")]}


def fly_quad(page: Any, serve: Serve) -> None:
    with serve.client() as api:
        take_control(page)
        arm_and_take_off(page, api, 6.0)
        page.select_option("#sp-type", "position")
        page.click("#sp-from-here")
        click_and_wait_result(page, "#btn-offboard-start")
        drag_slider_to(page, "#sp-north_m-slider", 12.0)
        drag_slider_to(page, "#sp-alt_m-slider", 12.0)
        # more than 3 m up at once: the page asks first, and the pilot says yes
        page.wait_for_selector("#confirm-dialog[open]", timeout=5_000)
        page.click("#confirm-ok")
        wait_for("the quad on its way", lambda: vehicle_state(api)["position_ned"]["north_m"] > 6,
                 30.0)


def fly_vtol(page: Any, serve: Serve) -> None:
    with serve.client() as api:
        take_control(page)
        arm_and_take_off(page, api, 20.0)
        click_and_wait_result(page, "#btn-to-fw")
        wait_for("fixed-wing flight", lambda: vehicle_state(api)["vtol_state"] == "FW", 30.0)
        time.sleep(4.0)


def shoot_cockpit(browser: Any) -> list[dict[str, Any]]:
    """The walk of the layout probe, quad then VTOL, with the pictures of QUAD_SHOTS and
    VTOL_SHOTS; fails when the probe finds the layout broken."""
    shots: list[dict[str, Any]] = []
    for args, airframe, wanted in (
        (QUAD_SERVE_ARGS, "quad", QUAD_SHOTS),
        (VTOL_SERVE_ARGS, "vtol", VTOL_SHOTS),
    ):
        started = time.monotonic()

        def walk_for(page: Any, reach: list[str], wanted: Any = wanted) -> Walk:
            return Walk(page, reach, shots=wanted, shot_dir=IMG_DIR)

        with Serve(extra_args=args).running() as serve:
            if airframe == "quad":
                with serve.client() as api:
                    walk = walk_quad(browser, serve, api, walk_for)
            else:
                walk = walk_vtol(browser, serve, walk_for)
        if walk.problems or walk.moved():
            raise AssertionError("\n".join(walk.problems + walk.moved()))
        seconds = time.monotonic() - started
        print(f"cockpit {airframe}: {len(walk.shot_paths)} pictures after {seconds:.1f} s")
        shots += [
            {"image": str(path.relative_to(ROOT)), "walk": airframe, "wall_s": round(seconds, 1)}
            for path in walk.shot_paths
        ]
    return shots


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
        page.wait_for_timeout(4500)  # the page moves viser's WebGL notice to its views' bar
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
