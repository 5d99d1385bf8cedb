"""The page's layout in Chromium, in every state of a flight (observer, in control, a
takeover request, flying offboard, the vehicle's link lost, sticks, a failsafe; four vehicles
on the server; a VTOL in fixed-wing flight) at 1024x768, 1280x800 and 1920x1080, light and
dark: every visible control and panel lies inside the window or inside the column that
scrolls it, nothing is clipped by a box that hides its overflow, no two controls overlap, no
button's label is cut, the top bar keeps one row, the alert area never covers the views, the
primary flight controls are in sight at 1280x800 without scrolling, and the command buttons
stay where they are whatever the state. The standard flight is flown from the page at
1280x800 without anything scrolling. Also: the shortcut list opens with '?'; the theme
follows the system and the pilot's choice is kept for the next visit."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from .flows import (
    arm_and_take_off,
    click_and_wait_result,
    open_dashboard,
    settle_vehicle,
    start_offboard_here,
    take_control,
)
from .harness import CHROMIUM, Serve, vehicle_state, wait_for
from .pausing import sim_paused

# A function the page evaluates: every visible control's and panel's box checked, a list of
# what is wrong.
LAYOUT_PROBLEMS = (Path(__file__).with_name("layout_probe.js")).read_text()

# a long ask: the probe looks at the question at every size and theme before it is answered
SERVE_ARGS = ["--sim-count", "4", "--sim-speed", "2", "--takeover-ask-s", "60"]
SIZES = [(1024, 768), (1280, 800), (1920, 1080)]
COCKPIT = (1280, 800)
THEMES = ["light", "dark"]
PAGE_TIMEOUT_MS = 30_000
# Where these are must not depend on the state (a text that grows, a banner, a button that
# comes or goes): the commands, the offboard panel, the top bar's control buttons, the sticks.
FIXED = [
    "btn-arm",
    "btn-disarm",
    "takeoff-alt",
    "btn-takeoff",
    "btn-land",
    "btn-rtl",
    "btn-hold",
    "btn-kill",
    "mode-select",
    "btn-set-mode",
    "sp-type",
    "sp-from-here",
    "btn-offboard-start",
    "btn-offboard-stop",
    "btn-brake",
    "kbd-enable",
    "control-slot",
    "sticks-enable",
    "sticks-posctl",
    "stick-left",
    "stick-right",
    "map-follow",
]
# The primary flight controls, in sight at 1280x800 without scrolling anything.
REACH = [
    "control-slot",
    "btn-arm",
    "btn-disarm",
    "btn-takeoff",
    "btn-land",
    "btn-rtl",
    "btn-hold",
    "btn-kill",
    "btn-set-mode",
    "btn-offboard-start",
    "btn-offboard-stop",
    "btn-brake",
    "kbd-enable",
    "sticks-enable",
    "sticks-posctl",
    "stick-left",
    "stick-right",
]
REACH_VTOL = [*REACH, "btn-to-fw", "btn-to-mc"]
# Two frames after a change of size or theme, the page at its top.
SETTLED = """() => new Promise((done) => {
  window.scrollTo(0, 0);
  requestAnimationFrame(() => requestAnimationFrame(done));
})"""
# Records every scroll but the message log's own (it follows its newest line).
SCROLL_WATCH = """
window.__scrolls = [];
document.addEventListener("scroll", (e) => {
  const t = e.target;
  const what = t === document ? "the page" : (t.id || t.className || t.tagName);
  if (t.id !== "log") window.__scrolls.push(String(what));
}, true);
"""


@pytest.fixture(scope="module")
def chromium() -> Iterator[Any]:
    """A plain browser: each test opens its own context with its size and colour scheme."""
    if not CHROMIUM.exists():
        pytest.skip("/usr/bin/chromium is not installed (make chromium, as root)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    from .harness import CHROMIUM_ARGS

    with sync_api.sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True
        )
        try:
            yield browser
        finally:
            browser.close()


@pytest.fixture(scope="module")
def vtol_serve() -> Iterator[Serve]:
    server = Serve(extra_args=["--sim-airframe", "vtol", "--sim-speed", "2"])
    server.start()
    try:
        yield server
    finally:
        server.stop()
        server.discard_log()


def _context(chromium: Any, size: tuple[int, int] = COCKPIT, scheme: str = "dark") -> Any:
    # the page's CSP forbids eval, which string predicates need; the CSP test keeps it
    return chromium.new_context(
        viewport={"width": size[0], "height": size[1]}, color_scheme=scheme, bypass_csp=True
    )


def _open(chromium: Any, url: str, size: tuple[int, int], scheme: str) -> Any:
    page = _context(chromium, size, scheme).new_page()
    page.goto(f"{url}&scene=off")
    page.wait_for_function("document.getElementById('mode').textContent !== '–'", timeout=30_000)
    page.wait_for_selector(".map-vehicle", timeout=30_000)
    return page


def _problems(page: Any, page_may_scroll: bool = False) -> list[str]:
    found = page.evaluate(LAYOUT_PROBLEMS)
    assert found["controls"] > 30, "the page's controls were not found"
    problems: list[str] = found["problems"]
    if found["pageScrolls"] and not page_may_scroll:
        problems.append("the whole page scrolls: its columns should")
    return problems


class _Walk:
    """Probes one page in each state at every size and theme (switched in the page), keeping
    what is wrong and where the FIXED controls were."""

    def __init__(self, page: Any, reach: list[str]) -> None:
        self.page = page
        self.reach = reach
        self.problems: list[str] = []
        self.boxes: dict[str, dict[str, dict[str, list[int] | None]]] = {}

    def probe(self, state: str, *, record: bool = True) -> None:
        for width, height in SIZES:
            self.page.set_viewport_size({"width": width, "height": height})
            for scheme in THEMES:
                self.page.emulate_media(color_scheme=scheme)
                self.page.wait_for_function(
                    f"document.documentElement.dataset.theme === '{scheme}'", timeout=5_000
                )
                self.page.evaluate(SETTLED)
                cockpit = (width, height) == COCKPIT
                found = self.page.evaluate(
                    LAYOUT_PROBLEMS, {"reach": self.reach if cockpit else [], "boxes": FIXED}
                )
                where = f"{state}, {width}x{height} {scheme}"
                assert found["controls"] > 30, f"{where}: the page's controls were not found"
                self.problems += [f"{where}: {p}" for p in found["problems"] + found["unreachable"]]
                # below 1180 px the page takes two columns and scrolls as a whole
                if found["pageScrolls"] and width > 1180:
                    self.problems.append(f"{where}: the whole page scrolls")
                if record:
                    self.boxes.setdefault(f"{width}x{height} {scheme}", {})[state] = found["boxes"]
        self.page.set_viewport_size({"width": COCKPIT[0], "height": COCKPIT[1]})
        self.page.emulate_media(color_scheme="dark")

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


def _settle(api: httpx.Client, *, flying: bool) -> None:
    """settle_vehicle, once the vehicle has a global position (home): it arms only then."""
    wait_for(
        "a home position",
        lambda: (s := vehicle_state(api))["home"] is not None and s["global"] is not None,
        60.0,
    )
    settle_vehicle(api, flying=flying)


def _into_position_mode(page: Any, api: httpx.Client) -> None:
    page.click("#sticks-posctl")
    wait_for("POSCTL", lambda: vehicle_state(api)["mode"] == "POSCTL", 15.0)
    assert page.is_checked("#sticks-enable")


def _fly_right_stick_forward(page: Any, api: httpx.Client, metres: float) -> None:
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


def _click_map(page: Any, api: httpx.Client, north_m: float, east_m: float) -> None:
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


def test_the_standard_flight_from_the_page_at_1280x800_scrolls_nothing(
    chromium: Any, serve: Serve, api: httpx.Client
) -> None:
    _settle(api, flying=False)
    page = open_dashboard(_context(chromium), serve.url, scene=False, init_script=SCROLL_WATCH)
    try:
        take_control(page)
        arm_and_take_off(page, api, 6.0)
        start_offboard_here(page, api)
        _into_position_mode(page, api)
        _fly_right_stick_forward(page, api, 3.0)
        _click_map(page, api, 30.0, 30.0)
        wait_for(
            "on its way to the clicked point",
            lambda: (p := vehicle_state(api)["position_ned"])["north_m"] > 8 and p["east_m"] > 8,
            30.0,
        )
        click_and_wait_result(page, "#btn-rtl")
        wait_for("RTL", lambda: vehicle_state(api)["mode"] == "RTL", 10.0)
        assert page.evaluate("window.__scrolls") == []
        scrolled = page.evaluate(
            "[window.scrollY, ...[...document.querySelectorAll('.column')].map((c) => c.scrollTop)]"
        )
        assert scrolled == [0, 0, 0, 0]
    finally:
        page.context.close()


def test_the_layout_holds_in_every_state_of_a_flight(
    chromium: Any, serve: Serve, api: httpx.Client
) -> None:
    _settle(api, flying=True)
    context = _context(chromium)
    page = open_dashboard(context, serve.url, scene=False)
    walk = _Walk(page, REACH)
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
            asking = _Walk(asker, REACH)
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
                "['armed', 'landed', 'mode', 'vtol-state'].every((id) =>"
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
        # flying OFFBOARD again ends it at once, however it was announced
        start_offboard_here(page, api)
        page.wait_for_selector('.alert[data-kind="failsafe"]', state="detached", timeout=3_000)

        _into_position_mode(page, api)
        walk.probe("sticks")
    finally:
        context.close()
    assert not walk.problems, "\n".join(walk.problems)
    assert not walk.moved(), "\n".join(walk.moved())


def test_a_vtol_in_fixed_wing_flight_keeps_the_layout(chromium: Any, vtol_serve: Serve) -> None:
    context = _context(chromium)
    page = open_dashboard(context, vtol_serve.url, scene=False)
    walk = _Walk(page, REACH_VTOL)
    try:
        with vtol_serve.client() as api:
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
    assert not walk.problems, "\n".join(walk.problems)
    assert not walk.moved(), "\n".join(walk.moved())


@pytest.mark.parametrize("size", [(1024, 768), (768, 1024)], ids=["landscape", "portrait"])
def test_on_a_tablet_the_page_scrolls_and_nothing_is_cut_or_overlaps(
    chromium: Any, serve: Any, size: tuple[int, int]
) -> None:
    context = chromium.new_context(
        viewport={"width": size[0], "height": size[1]}, has_touch=True, color_scheme="dark"
    )
    page = context.new_page()
    try:
        page.goto(f"{serve.url}&scene=off")
        page.wait_for_selector(".map-vehicle", timeout=30_000)
        problems = _problems(page, page_may_scroll=True)
        assert not problems, "\n".join(problems)
        # fingers get bigger targets
        arm = page.locator("#btn-arm").bounding_box()
        assert arm is not None
        assert arm["height"] >= 34
        # the views are in sight at the top in portrait, beside the commands in landscape
        views = page.locator(".views-panel").bounding_box()
        assert views is not None
        assert views["y"] < size[1] / 2
        assert views["height"] > 300
    finally:
        context.close()


def test_shortcut_keys_toggle_views_and_list_themselves(chromium: Any, serve: Any) -> None:
    page = _open(chromium, serve.url, (1280, 800), "dark")
    try:
        assert page.is_visible("#map")
        page.keyboard.press("m")
        page.wait_for_selector("#map", state="hidden", timeout=5_000)
        assert not page.is_checked("#map-enable")
        page.keyboard.press("m")
        page.wait_for_selector("#map", state="visible", timeout=5_000)
        page.keyboard.press("?")
        page.wait_for_selector("#shortcuts:not(.hidden)", timeout=5_000)
        listed = page.text_content("#shortcuts") or ""
        for key in ("W", "Space", "M", "V", "T", "?", "Esc"):
            assert key in listed
        page.keyboard.press("Escape")
        page.wait_for_selector("#shortcuts", state="hidden", timeout=5_000)
        # a key typed in a field is the field's, not a shortcut
        page.focus("#client-label")
        page.keyboard.press("m")
        assert page.is_visible("#map")
    finally:
        page.context.close()


def test_theme_follows_the_system_until_the_pilot_picks_one_kept_for_next_time(
    chromium: Any, serve: Any
) -> None:
    page = _open(chromium, serve.url, (1280, 800), "light")
    try:
        root = "document.documentElement.dataset"
        assert page.evaluate(f"{root}.theme") == "light"
        background = page.evaluate("getComputedStyle(document.body).backgroundColor")
        page.click("#theme-toggle")  # auto -> light
        page.click("#theme-toggle")  # light -> dark
        assert page.evaluate(f"[{root}.themeChoice, {root}.theme]") == ["dark", "dark"]
        assert page.evaluate("getComputedStyle(document.body).backgroundColor") != background
        page.reload()
        page.wait_for_function("document.getElementById('mode').textContent !== '–'")
        assert page.evaluate(f"{root}.theme") == "dark"
        page.keyboard.press("t")  # dark -> auto: the system's light again
        assert page.evaluate(f"[{root}.themeChoice, {root}.theme]") == ["auto", "light"]
        page.emulate_media(color_scheme="dark")
        page.wait_for_function(f"{root}.theme === 'dark'", timeout=5_000)
    finally:
        page.context.close()
