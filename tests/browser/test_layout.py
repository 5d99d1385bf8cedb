"""The page's layout in Chromium, in every state of a flight (observer, in control, a
takeover request, flying offboard, the vehicle's link lost, sticks, a failsafe; four vehicles
on the server; a VTOL in fixed-wing flight) at 1024x768, 1280x800 and 1920x1080, light and
dark: every visible control and panel lies inside the window or inside the column that
scrolls it, nothing is clipped by a box that hides its overflow, no two controls overlap, no
button's label is cut, the top bar keeps one row, the alert area never covers the views, the
primary flight controls are in sight at 1280x800 without scrolling, and the command buttons
stay where they are whatever the state. The link's widest loss figures are read whole at
every size, on the quad and the VTOL; the top bar holds the widest text of each of its slots
(drawn by the page from its own state messages) at every width from 1024 to 1920 px, with the
server there and lost: its slots are of fixed width within each of its three width regimes
(only the spacer between them grows), which the test checks, so the whole page is probed at
the three standard widths and the top bar alone at each regime's two ends. The standard flight
is flown from the page at 1280x800 without anything scrolling. Also: the shortcut list opens
with '?'; the theme follows the system and the pilot's choice is kept for the next visit."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from .cockpit_walk import (
    LAYOUT_PROBLEMS,
    QUAD_SERVE_ARGS,
    SIZES,
    VTOL_SERVE_ARGS,
    Walk,
    click_map,
    fly_right_stick_forward,
    into_position_mode,
    new_context,
    settle,
    walk_quad,
    walk_vtol,
)
from .flows import (
    arm_and_take_off,
    click_and_wait_result,
    open_dashboard,
    start_offboard_here,
    take_control,
)
from .harness import Serve, vehicle_state, wait_for

SERVE_ARGS = QUAD_SERVE_ARGS
# Records every scroll but the message log's own (it follows its newest line).
SCROLL_WATCH = """
window.__scrolls = [];
document.addEventListener("scroll", (e) => {
  const t = e.target;
  const what = t === document ? "the page" : (t.id || t.className || t.tagName);
  if (t.id !== "log") window.__scrolls.push(String(what));
}, true);
"""
# The link's loss figures as the test sets them (window.__linkLoss, [in, out] in %, null for
# not known) in every state the page's telemetry socket brings: the page draws them itself.
LINK_LOSS = """
window.__linkLoss = null;
const PageSocket = window.WebSocket;
window.WebSocket = class extends PageSocket {
  set onmessage(handler) {
    super.onmessage = (event) => {
      const message = JSON.parse(event.data);
      if (window.__linkLoss && message.type === "state" && message.link_quality) {
        [message.link_quality.loss_in_pct, message.link_quality.loss_out_pct] = window.__linkLoss;
        event = new MessageEvent("message", { data: JSON.stringify(message) });
      }
      handler(event);
    };
  }
  get onmessage() { return super.onmessage; }
};
"""
# The widest figures the page can write (three digits each way), and the unknown ones.
WORST_LINK_LOSS = {(100.0, 100.0): "↓100% ↑100%", (None, None): "↓? ↑?"}
# The widest text the page writes in each slot of the top bar, in every state and vehicle list
# the page's telemetry socket brings (the page draws them itself): a link lost for 59 min
# with 100 % lost each way, signing that fails, the longest mode name of modes.js flown and
# wanted, ON GROUND, Ready to fly, three-digit vehicle ids, a VTOL's transition; and, once
# window.__offline is set, the socket refused, so the page says it is reconnecting (its
# sockets are in window.__telemetry).
WORST_TEXTS = """
window.__offline = false;
window.__telemetry = [];
const PageSocket = window.WebSocket;
window.WebSocket = class extends PageSocket {
  constructor(url, ...rest) {
    const telemetry = String(url).includes("telemetry");
    super(telemetry && window.__offline ? "ws://127.0.0.1:9/" : url, ...rest);
    if (telemetry) window.__telemetry.push(this);
  }
  set onmessage(handler) {
    super.onmessage = (event) => {
      const message = JSON.parse(event.data);
      if (message.type === "state") {
        Object.assign(message, {
          connected: false, armed: false, mode: "FOLLOW_TARGET", user_mode: "FOLLOW_TARGET",
          landed_state: "ON_GROUND",
        });
        // a VTOL in its longest state, a transition
        if (message.vtol_state && message.vtol_state !== "UNDEFINED") {
          message.vtol_state = "TRANSITION_TO_FW";
        }
        const ages = message.message_ages_s || {};
        for (const kind of Object.keys(ages)) ages[kind] = 3540;
        Object.assign(message.link_quality || {}, { loss_in_pct: 100, loss_out_pct: 100 });
        Object.assign(message.arming_checks || {}, { verdict: "ready", ready: true });
        // signing on, the vehicle's frames failing it
        const signing = (message.link || {}).signing || {};
        Object.assign(signing, { enabled: true, vehicles_signed: false });
      } else if (message.type === "vehicles" && message.vehicles.length) {
        const first = message.vehicles[0];
        message.vehicles.push(
          { ...first, id: 254, type: "VTOL_TILTROTOR" }, { ...first, id: 255, type: "FIXED_WING" },
        );
      }
      handler(new MessageEvent("message", { data: JSON.stringify(message) }));
    };
  }
  get onmessage() { return super.onmessage; }
};
"""
WORST_DRAWN = """(cockpit) => {
  const text = (id) => document.getElementById(id).textContent;
  return text("link-health") === "LOST · 59 min" && text("link-loss") === "↓100% ↑100%"
    && text("mode") === "FOLLOW_TARGET" && text("user-mode") === "FOLLOW_TARGET"
    && text("landed") === "ON GROUND" && text("ready-to-fly") === "Ready to fly"
    && text("signing") === "SIGN FAIL"
    && document.querySelector("#vehicle-select option[value='255']") !== null
    && (cockpit !== "vtol" || text("vtol-state") === "→ FW");
}"""
# The top bar's width regimes (web/style.css's media queries on it): within one, every slot
# has a fixed width and only the spacer grows, so a text whole in its slot at a regime's
# narrow end is whole at every width of the regime, and a bar on one row at the narrow end is
# on one row up to the wide end. The test checks that premise (every box of the bar but the
# spacer the same at both ends) and probes the whole page at the three standard widths, the
# top bar alone at the regimes' other ends (its texts change nothing else: a top bar that
# wraps is off its row).
BAR_REGIMES = [(1024, 1180), (1181, 1440), (1441, 1920)]
PAGE_WIDTHS = {width for width, _ in SIZES}
BAR_WIDTHS = sorted({width for regime in BAR_REGIMES for width in regime} | PAGE_WIDTHS)
# Each box inside the top bar but the spacer, by its place in the bar: [path, width, height].
BAR_BOXES = """() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(() => {
  const bar = document.getElementById("topbar");
  const path = (el) => {
    const steps = [];
    for (let e = el; e !== bar; e = e.parentElement) {
      const index = [...e.parentElement.children].indexOf(e);
      steps.unshift(`${e.tagName}${e.id ? "#" + e.id : ""}:${index}`);
    }
    return steps.join(" > ");
  };
  done([...bar.querySelectorAll("*")].filter((el) => !el.classList.contains("spacer"))
    .map((el) => { const r = el.getBoundingClientRect(); return [path(el), r.width, r.height]; }));
})))"""


@pytest.fixture(scope="module")
def vtol_serve() -> Iterator[Serve]:
    with Serve(extra_args=VTOL_SERVE_ARGS).running() as server:
        yield server


def _open(chromium: Any, url: str, size: tuple[int, int], scheme: str) -> Any:
    page = new_context(chromium, size, scheme).new_page()
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


def test_the_standard_flight_from_the_page_at_1280x800_scrolls_nothing(
    chromium: Any, serve: Serve, api: httpx.Client
) -> None:
    settle(api, flying=False)
    page = open_dashboard(new_context(chromium), serve.url, scene=False, init_script=SCROLL_WATCH)
    try:
        take_control(page)
        arm_and_take_off(page, api, 6.0)
        start_offboard_here(page, api)
        into_position_mode(page, api)
        fly_right_stick_forward(page, api, 3.0)
        click_map(page, api, 30.0, 30.0)
        wait_for(
            "on its way to the clicked point",
            lambda: (p := vehicle_state(api)["position_ned"])["north_m"] > 8 and p["east_m"] > 8,
            30.0,
        )
        answer = click_and_wait_result(page, "#btn-rtl", expect="Return: ")
        # as for the map point: a late ACK on a loaded machine, what counts is that it returns
        assert "ACCEPTED" in answer or "TIMEOUT" in answer, answer
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
    walk = walk_quad(chromium, serve, api, Walk)
    assert not walk.problems, "\n".join(walk.problems)
    assert not walk.moved(), "\n".join(walk.moved())


def test_a_vtol_in_fixed_wing_flight_keeps_the_layout(chromium: Any, vtol_serve: Serve) -> None:
    walk = walk_vtol(chromium, vtol_serve, Walk)
    assert not walk.problems, "\n".join(walk.problems)
    assert not walk.moved(), "\n".join(walk.moved())


@contextlib.contextmanager
def _cockpit(
    chromium: Any, request: pytest.FixtureRequest, cockpit: str, init_script: str
) -> Iterator[tuple[Any, Walk]]:
    """A page of the quad's or the VTOL's server, with ``init_script``, its vehicle drawn."""
    server: Serve = request.getfixturevalue("serve" if cockpit == "quad" else "vtol_serve")
    page = open_dashboard(new_context(chromium), server.url, scene=False, init_script=init_script)
    try:
        page.wait_for_selector(".map-vehicle", timeout=30_000)
        if cockpit == "vtol":
            page.wait_for_selector("#vtol-panel:not(.hidden)", timeout=30_000)
        yield page, Walk(page, [])
    finally:
        page.context.close()


@pytest.mark.parametrize("cockpit", ["quad", "vtol"])
def test_the_link_slot_shows_the_widest_loss_whole_at_every_size(
    chromium: Any, request: pytest.FixtureRequest, cockpit: str
) -> None:
    with _cockpit(chromium, request, cockpit, LINK_LOSS) as (page, walk):
        for (loss_in, loss_out), text in WORST_LINK_LOSS.items():
            page.evaluate("(loss) => { window.__linkLoss = loss; }", [loss_in, loss_out])
            page.wait_for_function(
                "(text) => document.getElementById('link-loss').textContent === text",
                arg=text, timeout=10_000,
            )
            walk.probe(f"link loss {text}", record=False)
            # the tooltip says them too
            title = page.get_attribute("#link-slot", "title") or ""
            shown = [f"{v:.0f}%" if v is not None else "?" for v in (loss_in, loss_out)]
            assert f"frames lost from it {shown[0]} and to it {shown[1]}" in title, title
        assert not walk.problems, "\n".join(walk.problems)


@pytest.mark.parametrize("cockpit", ["quad", "vtol"])
def test_the_top_bar_holds_its_widest_texts_at_every_width(
    chromium: Any, request: pytest.FixtureRequest, cockpit: str
) -> None:
    sizes = [(width, 800) for width in BAR_WIDTHS if width in PAGE_WIDTHS]
    bar_sizes = [(width, 800) for width in BAR_WIDTHS if width not in PAGE_WIDTHS]
    with _cockpit(chromium, request, cockpit, WORST_TEXTS) as (page, walk):
        try:
            page.wait_for_function(WORST_DRAWN, arg=cockpit, timeout=30_000)
        except Exception as e:
            shown = page.evaluate(
                "['link-health', 'link-loss', 'mode', 'user-mode', 'landed', 'ready-to-fly',"
                " 'vehicle-select', 'vtol-state', 'signing']"
                ".map((id) => document.getElementById(id).textContent)"
            )
            raise AssertionError(f"the widest texts were not drawn: {shown}") from e
        # the widest name in the vehicle menu shown (as the pilot would see it picked)
        page.evaluate("document.getElementById('vehicle-select').value = '255'")
        picked = "document.getElementById('vehicle-select').selectedOptions[0].textContent"
        assert page.evaluate(picked) == "255 · plane"
        walk.probe("widest texts", record=False, sizes=sizes)
        walk.probe("widest texts", record=False, sizes=bar_sizes, scope="#topbar")
        walk.problems += _bar_boxes_that_change_within_a_regime(page, "widest texts")
        # the server lost: the SERVER box says the page is reconnecting
        page.evaluate("window.__offline = true; window.__telemetry.forEach((s) => s.close())")
        page.wait_for_function(
            "document.getElementById('conn-status').textContent === 'reconnecting…'",
            timeout=10_000,
        )
        walk.probe("widest texts, the server lost", record=False, sizes=sizes)
        walk.probe("widest texts, the server lost", record=False, sizes=bar_sizes,
                   scope="#topbar")
        walk.problems += _bar_boxes_that_change_within_a_regime(
            page, "widest texts, the server lost"
        )
        assert not walk.problems, "\n".join(walk.problems)


def _bar_boxes_that_change_within_a_regime(page: Any, state: str) -> list[str]:
    """Each box of the top bar (the spacer left out) whose size differs between the two
    ends of a width regime: the premise of probing the bar at the ends only."""
    changed = []
    for narrow, wide in BAR_REGIMES:
        ends = []
        for width in (narrow, wide):
            page.set_viewport_size({"width": width, "height": 800})
            ends.append(page.evaluate(BAR_BOXES))
        if [path for path, _, _ in ends[0]] != [path for path, _, _ in ends[1]]:
            changed.append(f"{state}: the top bar holds other elements at {narrow} and {wide} px")
            continue
        changed += [
            f"{state}: {path} is {w0:.1f}x{h0:.1f} at {narrow} px, {w1:.1f}x{h1:.1f} at {wide} px"
            for (path, w0, h0), (_, w1, h1) in zip(ends[0], ends[1], strict=True)
            if abs(w0 - w1) > 0.01 or abs(h0 - h1) > 0.01
        ]
    page.set_viewport_size({"width": 1280, "height": 800})
    return changed


@pytest.mark.parametrize("size", [(1024, 768), (1280, 800), (1920, 1080)], ids=str)
def test_no_label_is_cut_and_every_greyed_out_control_says_why(
    chromium: Any, serve: Serve, api: httpx.Client, size: tuple[int, int]
) -> None:
    settle(api, flying=False)
    page = _open(chromium, serve.url, size, "light")
    try:
        page_scrolls = size[0] <= 1180  # two columns: the page scrolls as a whole
        problems = [f"observer: {p}" for p in _problems(page, page_scrolls)]
        # an observer's flying controls are greyed out, each saying what to do
        assert page.get_attribute("#btn-arm", "title") == "Take control first"
        assert page.is_disabled("#btn-takeoff")
        take_control(page)
        problems += [f"in control: {p}" for p in _problems(page, page_scrolls)]
        assert not page.get_attribute("#btn-arm", "title")
        # the amber badge's two lines: disarmed in OFFBOARD with no stream, Arm goes by HOLD
        page.select_option("#mode-select", "OFFBOARD")
        click_and_wait_result(page, "#btn-set-mode")
        page.wait_for_function(
            "document.getElementById('ready-to-fly').classList.contains('warn')", timeout=20_000
        )
        problems += [f"amber badge: {p}" for p in _problems(page, page_scrolls)]
        page.select_option("#mode-select", "HOLD")
        click_and_wait_result(page, "#btn-set-mode")
        # the ready popover and the words of the page
        page.click("#ready-to-fly")
        problems += [f"ready popover: {p}" for p in _problems(page, page_scrolls)]
        page.keyboard.press("Escape")
        page.click("#shortcuts-open")
        words = page.text_content("#shortcuts") or ""
        for word in ("lease", "Deadman", "Envelope", "Intent", "Wanted"):
            assert word in words, word
        # (the list covers the page, as a dialog does: only its own words are looked at)
        problems += [f"words: {p}" for p in _problems(page, page_scrolls) if "label cut" in p]
        page.keyboard.press("Escape")
        assert not problems, "\n".join(problems)
    finally:
        page.context.close()


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
