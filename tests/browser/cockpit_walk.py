"""The cockpit's states, walked on a live page by the layout test and the screenshot script:
the layout probe (layout_probe.js) at every size and theme in each state, where the command
buttons were, and pictures of chosen states."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from .flows import (
    arm_and_take_off,
    click_and_wait_result,
    open_dashboard,
    settle_vehicle,
    start_offboard_here,
    take_control,
)
from .harness import Serve, vehicle_state, wait_for
from .pausing import sim_paused

# A function the page evaluates: every visible control's and panel's box checked, a list of
# what is wrong.
LAYOUT_PROBLEMS = (Path(__file__).with_name("layout_probe.js")).read_text()

SIZES = [(1024, 768), (1280, 800), (1920, 1080)]
COCKPIT = (1280, 800)
THEMES = ["light", "dark"]
PAGE_TIMEOUT_MS = 30_000
# A long ask: the probe looks at the question at every size and theme before it is answered.
QUAD_SERVE_ARGS = ["--sim-count", "4", "--sim-speed", "1", "--takeover-ask-s", "60"]
VTOL_SERVE_ARGS = ["--sim-airframe", "vtol", "--sim-speed", "2"]
# Where these are must not depend on the state (a text that grows, a banner, a button that
# comes or goes): the commands, the offboard panel, the top bar's control buttons, the sticks.
FIXED = [
    "btn-arm", "btn-disarm", "takeoff-alt", "btn-takeoff", "btn-land", "btn-rtl", "btn-hold",
    "btn-kill", "mode-select", "btn-set-mode", "sp-type", "sp-from-here", "btn-offboard-start",
    "btn-offboard-stop", "btn-brake", "kbd-enable", "control-slot", "sticks-enable",
    "sticks-posctl", "stick-left", "stick-right", "map-follow", "instruments",
]  # fmt: skip
# The primary flight controls, in sight at 1280x800 without scrolling anything.
REACH = [
    "control-slot", "btn-arm", "btn-disarm", "btn-takeoff", "btn-land", "btn-rtl", "btn-hold",
    "btn-kill", "btn-set-mode", "btn-offboard-start", "btn-offboard-stop", "btn-brake",
    "kbd-enable", "sticks-enable", "sticks-posctl", "stick-left", "stick-right",
]  # fmt: skip
REACH_VTOL = [*REACH, "btn-to-fw", "btn-to-mc"]
# Two frames after a change of size or theme, the page at its top, then the layout probe
# with the given options: one call.
SETTLED_PROBE = f"""(options) => new Promise((done) => {{
  window.scrollTo(0, 0);
  requestAnimationFrame(() => requestAnimationFrame(() => done(({LAYOUT_PROBLEMS}
  )(options))));
}})"""


def new_context(browser: Any, size: tuple[int, int] = COCKPIT, scheme: str = "dark") -> Any:
    # the page's CSP forbids eval, which string predicates need; the CSP test keeps it
    return browser.new_context(
        viewport={"width": size[0], "height": size[1]}, color_scheme=scheme, bypass_csp=True
    )


@dataclass(frozen=True)
class Shot:
    """A picture of the whole page in one state: docs/img/<name>.png, or of one element."""

    name: str
    size: tuple[int, int] = COCKPIT
    scheme: str = "dark"
    selector: str = ""


class Walk:
    """Probes one page in each state at every size and theme (switched in the page), keeping
    what is wrong and where the FIXED controls were."""

    def __init__(
        self,
        page: Any,
        reach: list[str],
        shots: dict[str, list[Shot]] | None = None,
        shot_dir: Path | None = None,
    ) -> None:
        self.page = page
        self.reach = reach
        self.shots = shots or {}
        self.shot_dir = shot_dir
        self.shot_paths: list[Path] = []
        self.problems: list[str] = []
        self.boxes: dict[str, dict[str, dict[str, list[int] | None]]] = {}

    def probe(
        self,
        state: str,
        *,
        record: bool = True,
        sizes: list[tuple[int, int]] = SIZES,
        scope: str | None = None,
    ) -> None:
        """The probe at each size and theme; ``scope`` (a selector) checks only what lies
        inside it. One theme at a time, every size in it: a switch of theme restyles the
        whole page, a size only lays it out again."""
        for scheme in THEMES:
            self.page.emulate_media(color_scheme=scheme)
            self.page.wait_for_function(
                f"document.documentElement.dataset.theme === '{scheme}'", timeout=5_000
            )
            for width, height in sizes:
                self.page.set_viewport_size({"width": width, "height": height})
                cockpit = (width, height) == COCKPIT
                found = self.page.evaluate(
                    SETTLED_PROBE,
                    {"reach": self.reach if cockpit and not scope else [], "boxes": FIXED,
                     "scope": scope},
                )
                where = f"{state}, {width}x{height} {scheme}"
                least = 30 if scope is None else 0
                assert found["controls"] > least, f"{where}: the page's controls were not found"
                self.problems += [f"{where}: {p}" for p in found["problems"] + found["unreachable"]]
                # below 1180 px the page takes two columns and scrolls as a whole
                if found["pageScrolls"] and width > 1180:
                    self.problems.append(f"{where}: the whole page scrolls")
                if record:
                    self.boxes.setdefault(f"{width}x{height} {scheme}", {})[state] = found["boxes"]
                for shot in self.shots.get(state, []):
                    if shot.size == (width, height) and shot.scheme == scheme:
                        self.shoot(shot)
        self.page.set_viewport_size({"width": COCKPIT[0], "height": COCKPIT[1]})
        self.page.emulate_media(color_scheme="dark")

    def shoot(self, shot: Shot) -> None:
        if self.shot_dir is None:
            return
        path = self.shot_dir / f"{shot.name}.png"
        if shot.selector:
            self.page.locator(shot.selector).first.screenshot(path=str(path))
            # the element's picture scrolled it into view: back to the page as probed
            self.page.evaluate(
                "document.querySelectorAll('.column').forEach((c) => { c.scrollTop = 0; })"
            )
        else:
            self.page.screenshot(path=str(path))
        self.shot_paths.append(path)

    def moved(self) -> list[str]:
        """Each FIXED control whose box differs between states, with both boxes."""
        moved = []
        for where, by_state in self.boxes.items():
            first_state, first = next(iter(by_state.items()))
            for state, boxes in by_state.items():
                moved += [
                    f"{where}: #{name} {first[name]} {first_state}, {box} {state}"
                    for name, box in boxes.items()
                    if box != first[name]
                ]
        return moved


def settle(api: httpx.Client, *, flying: bool) -> None:
    """settle_vehicle, once the vehicle has a global position (home): it arms only then."""
    wait_for(
        "a home position",
        lambda: (s := vehicle_state(api))["home"] is not None and s["global"] is not None,
        60.0,
    )
    settle_vehicle(api, flying=flying)


def into_position_mode(page: Any, api: httpx.Client) -> None:
    page.click("#sticks-posctl")
    wait_for("POSCTL", lambda: vehicle_state(api)["mode"] == "POSCTL", 15.0)
    assert page.is_checked("#sticks-enable")


def fly_right_stick_forward(page: Any, api: httpx.Client, metres: float) -> None:
    start = vehicle_state(api)["position_ned"]
    pad = page.locator("#stick-right").bounding_box()
    assert pad is not None
    cx, cy = pad["x"] + pad["width"] / 2, pad["y"] + pad["height"] / 2
    page.mouse.move(cx, cy)
    page.mouse.down()
    page.mouse.move(cx, pad["y"] + pad["height"] * 0.15, steps=8)

    def moved_m() -> float:
        p = vehicle_state(api)["position_ned"]
        return math.hypot(p["north_m"] - start["north_m"], p["east_m"] - start["east_m"])

    wait_for(f"{metres} m flown with the stick", lambda: moved_m() > metres, 20.0)
    page.mouse.up()


def click_map(page: Any, api: httpx.Client, north_m: float, east_m: float) -> None:
    """Clicks the map north_m / east_m from the vehicle and answers the question: fly there."""
    import pymap3d

    here = vehicle_state(api)["global"]
    lat, lon, _ = pymap3d.ned2geodetic(north_m, east_m, 0.0, here["lat_deg"], here["lon_deg"], 0.0)
    point = page.evaluate("([a, b]) => window.skyhelm.map.pagePoint(a, b)", [lat, lon])
    page.mouse.click(point["x"], point["y"])
    page.fill("#map-goto-alt", "8")
    answer = click_and_wait_result(page, "#map-goto-go", expect="Go to the map point: ")
    # on a loaded machine the vehicle's ACK can come after the command's 3 x 0.5 s; whether it
    # flies there the caller checks
    assert "ACCEPTED" in answer or "TIMEOUT" in answer, answer


def walk_quad(browser: Any, serve: Serve, api: httpx.Client, walk_for: Any) -> Walk:
    """Observer with 4 vehicles on the server, in control, a takeover request (and the asking
    tab), flying offboard, the vehicle's link lost, PX4's offboard loss failsafe and its end,
    sticks. ``walk_for(page, reach)`` makes the Walk; it is returned with what it found."""
    settle(api, flying=True)
    context = new_context(browser)
    page = open_dashboard(context, serve.url, scene=False)
    walk: Walk = walk_for(page, REACH)
    try:
        page.wait_for_function(
            "document.querySelectorAll('.map-vehicle').length === 4", timeout=PAGE_TIMEOUT_MS
        )
        walk.probe("observer, 4 vehicles")
        # every folded section open, and the 3D scene's box beside the map (without starting
        # its software WebGL)
        page.evaluate(
            "document.querySelectorAll('details').forEach((d) => { d.open = true; });"
            "document.getElementById('views').classList.remove('no-scene')"
        )
        walk.probe("folds open, map and 3D", record=False)
        page.evaluate(
            "document.querySelectorAll('details').forEach((d) => { d.open = false; });"
            "document.getElementById('views').classList.add('no-scene')"
        )

        take_control(page)
        walk.probe("in control")

        asker = open_dashboard(context, serve.url, scene=False)
        try:
            asker.click("#take-control")
            page.bring_to_front()  # a tab behind another draws no frames
            page.wait_for_selector("#takeover-prompt:not(.hidden)", timeout=PAGE_TIMEOUT_MS)
            walk.probe("takeover request")
            page.click("#deny-control")
            # the asking tab: Ask for control and Force side by side, and why it was refused
            asker.wait_for_function(
                "document.getElementById('control-note').textContent.includes('denied')",
                timeout=PAGE_TIMEOUT_MS,
            )
            asker.bring_to_front()
            asking = Walk(asker, REACH)
            asking.probe("observer while another holds control", record=False)
            walk.problems += asking.problems
            page.bring_to_front()
        finally:
            asker.close()

        start_offboard_here(page, api)
        walk.probe("flying offboard")

        # the vehicle falls silent: the server is there, the vehicle is not, and what came
        # from it greys
        with sim_paused(serve):
            page.wait_for_selector('.alert[data-kind="link"]', timeout=PAGE_TIMEOUT_MS)
            page.wait_for_function(
                "['armed', 'landed', 'mode', 'user-mode', 'vtol-state'].every((id) =>"
                " document.getElementById(id).classList.contains('stale'))",
                timeout=PAGE_TIMEOUT_MS,
            )
            assert page.text_content("#conn-status") == "connected"
            assert (page.text_content("#link-health") or "").startswith("LOST")
            assert page.evaluate("document.getElementById('link-health').className") == "bad"
            walk.probe("link lost")
        page.wait_for_selector(
            '.alert[data-kind="link"]', state="detached", timeout=PAGE_TIMEOUT_MS
        )
        page.wait_for_function(
            "!document.getElementById('armed').classList.contains('stale')",
            timeout=PAGE_TIMEOUT_MS,
        )

        # the stream stopped with the link: PX4's offboard loss failsafe
        page.wait_for_selector('.alert[data-kind="failsafe"]', timeout=PAGE_TIMEOUT_MS)
        walk.probe("failsafe")
        # flying OFFBOARD again ends it at once, however it was announced (the answer line
        # emptied first: the same answer as before would read as none)
        page.evaluate("document.getElementById('result').textContent = ''")
        start_offboard_here(page, api)
        page.wait_for_selector('.alert[data-kind="failsafe"]', state="detached", timeout=3_000)

        into_position_mode(page, api)
        walk.probe("sticks")
    finally:
        context.close()
    return walk


def walk_vtol(browser: Any, serve: Serve, walk_for: Any) -> Walk:
    """A VTOL at rest, then in fixed-wing flight."""
    context = new_context(browser)
    page = open_dashboard(context, serve.url, scene=False)
    walk: Walk = walk_for(page, REACH_VTOL)
    try:
        with serve.client() as api:
            page.wait_for_selector("#vtol-panel:not(.hidden)", timeout=PAGE_TIMEOUT_MS)
            walk.probe("VTOL at rest")
            take_control(page)
            arm_and_take_off(page, api, 20.0)
            click_and_wait_result(page, "#btn-to-fw")
            wait_for("fixed-wing flight", lambda: vehicle_state(api)["vtol_state"] == "FW", 40.0)
            page.wait_for_function(
                "document.getElementById('vtol-state').textContent === 'FW'",
                timeout=PAGE_TIMEOUT_MS,
            )
            walk.probe("VTOL in fixed-wing flight")
    finally:
        context.close()
    return walk
