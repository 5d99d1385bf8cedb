"""Two tabs of the dashboard in Chromium against `skyhelm serve` with the simulated quad: a
pilot flies, a second tab asks for control and gets it, control is forced with a confirmation,
each tab always shows who controls; and the page as a client: reconnecting with backoff, a
rejected token, the mode menu, refusals shown with their reasons. Every test settles the
vehicle first, so they run in any order."""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import httpx
import pytest

from tests.waiting import holds_for_blocking

from . import flows
from .harness import Serve, altitude_m, speed_m_s, vehicle_state, wait_for

SERVE_ARGS = ["--sim-speed", "3"]
# Counts the telemetry sockets the page opens (the control socket lives in a worker).
COUNT_SOCKETS = """
window.__sockets = [];
const NativeWebSocket = window.WebSocket;
window.WebSocket = class extends NativeWebSocket {
  constructor(url, protocols) {
    super(url, protocols);
    if (String(url).includes("/ws/telemetry")) window.__sockets.push(performance.now());
  }
};
"""


def _holder(tab: Any) -> str:
    """Who controls, whole (the slot shows a short name, its tooltip the whole one)."""
    return str(tab.get_attribute("#holder", "title") or "")


def _wait_holder(tab: Any, starts: str) -> None:
    tab.wait_for_function(
        "([s]) => document.getElementById('holder').title.startsWith(s)",
        arg=[starts],
        timeout=15_000,
    )


def _name(tab: Any) -> str:
    """This tab's session name as the server shows it (the holder's name once in control)."""
    text = _holder(tab)
    assert text.startswith("you ("), text
    assert text.endswith(")"), text
    return text[len("you (") : -1]


def _first_tab_in_control(first: Any, second_page: Any, api: httpx.Client) -> str:
    """The vehicle on the ground, the first tab in control as the second tab shows; its name."""
    flows.settle_vehicle(api, flying=False)
    flows.take_control(first)
    name = _name(first)
    _wait_holder(second_page, name)
    return name


def _not_in_control(tab: Any) -> None:
    tab.wait_for_selector("#release", state="hidden", timeout=15_000)
    tab.wait_for_selector("#btn-arm[disabled]", timeout=10_000)


def test_pilot_flies_then_a_second_tab_asks_and_the_first_grants(
    page: Any, second_page: Any, api: httpx.Client
) -> None:
    first_name = _first_tab_in_control(page, second_page, api)
    assert "since" in (second_page.get_attribute("#holder-since", "title") or "")
    flows.arm_and_take_off(page, api, 5.0)
    flows.start_offboard_here(page, api)

    # keys: a live body-frame velocity intent while W is held, a brake when it is let go
    start = vehicle_state(api)["position_ned"]
    page.click("#kbd-state")
    page.keyboard.down("w")
    wait_for(
        "a body velocity forward",
        lambda: (
            (sp := vehicle_state(api)["setpoint"]) is not None
            and sp["type"] == "velocity_body"
            and sp["forward_m_s"] > 0
        ),
        10.0,
    )
    wait_for("forward speed above 1 m/s", lambda: speed_m_s(vehicle_state(api)) > 1.0, 15.0)
    page.keyboard.up("w")
    held = flows.wait_position_hold(api)
    p = held["position_ned"]
    assert math.hypot(p["north_m"] - start["north_m"], p["east_m"] - start["east_m"]) > 0.5

    # the second tab asks; the first sees who asks and a countdown, and grants
    assert second_page.text_content("#take-control") == "Ask for control"
    second_page.click("#take-control")
    page.wait_for_selector("#takeover-prompt:not(.hidden)", timeout=10_000)
    assert "asks to take control" in (page.text_content("#takeover-by") or "")
    assert (page.text_content("#takeover-countdown") or "").endswith(" s")
    page.click("#grant-control")
    _wait_holder(second_page, "you")
    second_name = _name(second_page)
    assert second_name != first_name

    # the old holder says who took control and stops sending; the stream never stopped
    _not_in_control(page)
    page.wait_for_function(
        "([n]) => document.getElementById('control-note').textContent.includes(n)",
        arg=[second_name],
        timeout=10_000,
    )
    _wait_holder(page, second_name)
    state = vehicle_state(api)
    assert state["mode"] == "OFFBOARD"
    assert state["stream"]["active"]

    # the new holder's panel shows the setpoint being flown, not the form's defaults
    assert second_page.input_value("#sp-type") == "position"
    flown = state["setpoint"]
    assert float(second_page.input_value("#sp-north_m")) == pytest.approx(flown["north_m"], abs=0.1)
    assert float(second_page.input_value("#sp-alt_m")) == pytest.approx(altitude_m(state), abs=0.8)

    # return from the new holder's tab
    flows.click_and_wait_result(second_page, "#btn-rtl")
    wait_for(
        "landed and disarmed",
        lambda: (s := vehicle_state(api))["landed_state"] == "ON_GROUND" and not s["armed"],
        60.0,
        every_s=0.25,
    )


def test_a_denied_request_says_so_in_the_asking_tab(
    page: Any, second_page: Any, api: httpx.Client
) -> None:
    _first_tab_in_control(page, second_page, api)
    second_page.click("#take-control")
    page.wait_for_selector("#takeover-prompt:not(.hidden)", timeout=10_000)
    page.click("#deny-control")
    second_page.wait_for_function(
        "document.getElementById('control-note').textContent.includes('denied')", timeout=10_000
    )
    assert _holder(page).startswith("you")
    assert not _holder(second_page).startswith("you")


CONFIRM_FORCE = "Sure?"
# The control slot's buttons whose label is cut, or that leave the slot or the window.
CONTROL_SLOT_CUT = """() => {
  const slot = document.getElementById('control-slot').getBoundingClientRect();
  const cut = [];
  for (const el of document.querySelectorAll('#control-slot button:not(.hidden)')) {
    const r = el.getBoundingClientRect();
    if (el.scrollWidth > el.clientWidth + 1) cut.push(`${el.id} label cut: ${el.textContent}`);
    if (r.left < slot.left - 1 || r.right > slot.right + 1
        || r.right > document.documentElement.clientWidth + 1) {
      cut.push(`${el.id} "${el.textContent}" at ${Math.round(r.left)}..${Math.round(r.right)} px, `
        + `its slot ${Math.round(slot.left)}..${Math.round(slot.right)} px`);
    }
  }
  return cut;
}"""


def test_force_takes_control_only_after_a_confirmation(
    page: Any, second_page: Any, api: httpx.Client
) -> None:
    first_name = _first_tab_in_control(page, second_page, api)
    second_page.click("#force-control")
    assert second_page.text_content("#force-control") == CONFIRM_FORCE
    # the question whole in the top bar, at the narrowest width and the others
    for width, height in [(1024, 768), (1280, 800), (1920, 1080)]:
        second_page.set_viewport_size({"width": width, "height": height})
        assert second_page.evaluate(CONTROL_SLOT_CUT) == [], f"{width}x{height}"
    second_page.set_viewport_size({"width": 1280, "height": 800})
    holds_for_blocking(
        "the first tab still in control",
        lambda: api.get("/vehicles/1/control").json()["holder"] == first_name,
        0.5,
    )
    second_page.click("#force-control")
    _wait_holder(second_page, "you")
    _not_in_control(page)
    page.wait_for_function(
        "document.getElementById('control-note').textContent.startsWith('Control taken by')",
        timeout=10_000,
    )
    assert "Control taken by" in (page.text_content("#banner") or "")


TAKEN_SHOWN = """() => [document.getElementById('banner').textContent,
  ...Array.from(document.querySelectorAll('#alerts .alert[data-kind="control"]'),
                (e) => e.textContent)].filter((t) => t.includes('Control taken by'))"""


def test_a_tab_that_takes_control_back_no_longer_says_it_was_taken(
    page: Any, api: httpx.Client
) -> None:
    """A script forces control from the tab, then gives it back; the tab takes control again
    and sends: it no longer says "Control taken by the script: this tab no longer sends
    anything", neither in its banner nor in the alert area."""
    flows.settle_vehicle(api, flying=False)
    flows.take_control(page)
    taken = api.post("/vehicles/1/control",
                     json={"client_name": "script", "takeover": True, "force": True})
    assert taken.status_code == 200, taken.text
    _not_in_control(page)
    page.wait_for_function(f"({TAKEN_SHOWN})().length === 2", timeout=10_000)
    api.delete("/vehicles/1/control", headers={"X-Lease-Id": taken.json()["lease_id"]})
    _wait_holder(page, "nobody")
    page.wait_for_function(
        "Array.from(document.getElementById('log').children, (e) => e.textContent).some("
        "(t) => t.endsWith('control released: nobody holds it (was pilot · script)'))",
        timeout=10_000,
    )

    flows.take_control(page)
    assert page.evaluate(TAKEN_SHOWN) == []
    assert page.locator("#btn-arm").is_enabled()


def test_a_tab_that_hands_over_says_it_handed_over_not_that_control_was_taken(
    page: Any, api: httpx.Client
) -> None:
    """The pilot answers a script's request with Hand over: the tab says it handed control
    over (and sends nothing more), never the warning "Control taken by …" of a takeover."""
    flows.settle_vehicle(api, flying=False)
    flows.take_control(page)
    with ThreadPoolExecutor(max_workers=1) as pool:
        asked = pool.submit(
            api.post, "/vehicles/1/control",
            json={"client_name": "asking script", "takeover": True}, timeout=30.0,
        )  # fmt: skip
        page.wait_for_selector("#takeover-prompt:not(.hidden)", timeout=10_000)
        page.click("#grant-control")
        answer = asked.result()
    assert answer.status_code == 200, answer.text
    _not_in_control(page)
    page.wait_for_function(
        "document.getElementById('control-note').textContent"
        ".startsWith('Control handed over to pilot · asking script')",
        timeout=10_000,
    )
    assert page.evaluate(TAKEN_SHOWN) == []
    assert not [a for a in page.evaluate("window.skyhelm.alertLog")
                if a["text"].startswith("Control taken by")]  # fmt: skip
    assert (page.text_content("#banner") or "").endswith("this tab no longer sends anything")
    api.delete("/vehicles/1/control", headers={"X-Lease-Id": answer.json()["lease_id"]})


def test_every_tab_shows_who_controls_and_the_label_is_editable(
    page: Any, second_page: Any, api: httpx.Client
) -> None:
    flows.settle_vehicle(api, flying=False)
    _wait_holder(page, "nobody")

    def label(text: str) -> None:
        page.fill("#client-label", text)
        page.press("#client-label", "Enter")
        page.click("#kbd-state")

    try:
        label("Ground station A")
        assert page.evaluate("localStorage.getItem('skyhelm.clientLabel')") == "Ground station A"
        flows.take_control(page)
        name = _name(page)
        assert "Ground station A" in name
        _wait_holder(second_page, name)
        label("Ground station B")  # in control: the session is renamed at once
        _wait_holder(second_page, name.replace("Ground station A", "Ground station B"))
        _wait_holder(page, "you (" + name.replace("Ground station A", "Ground station B"))
        page.click("#release")
        _wait_holder(page, "nobody")
        _wait_holder(second_page, "nobody")
    finally:
        page.evaluate("localStorage.removeItem('skyhelm.clientLabel')")


def test_mode_menu_lists_this_vehicles_modes_and_follows_the_mode(
    page: Any, api: httpx.Client
) -> None:
    flows.settle_vehicle(api, flying=True)
    modes = page.eval_on_selector_all("#mode-select option", "os => os.map(o => o.value)")
    assert "VTOL_TAKEOFF" not in modes
    assert "TERMINATION" not in modes
    assert {"POSCTL", "OFFBOARD", "HOLD", "TAKEOFF", "LAND", "RTL"} <= set(modes)
    by_type = page.evaluate(
        "['FIXED_WING', 'VTOL_FIXEDROTOR', 'GROUND_ROVER'].map(t => window.skyhelm.modesFor(t))"
    )
    plane, vtol, rover = by_type
    assert "VTOL_TAKEOFF" in vtol
    assert "VTOL_TAKEOFF" not in plane
    assert not {"TAKEOFF", "LAND"} & set(rover)
    assert "HOLD" in rover
    page.wait_for_function(
        "document.getElementById('mode-select').value === 'HOLD'", timeout=10_000
    )


def test_refusals_show_their_reason_and_field(page: Any, api: httpx.Client) -> None:
    flows.settle_vehicle(api, flying=True)
    flows.take_control(page)
    page.fill("#repo-north", "5000")
    text = flows.click_and_wait_result(page, "#btn-repo-offset", expect="422")
    assert "north_m" in text, text
    assert "envelope" in text, text
    page.fill("#takeoff-alt", "500")
    text = flows.click_and_wait_result(page, "#btn-takeoff", expect="422")
    assert "altitude_m" in text, text


def test_reconnects_with_a_bounded_backoff_after_the_server_stops(
    browser: Any, serve: Serve
) -> None:
    tab = flows.open_dashboard(browser, serve.url, scene=False, init_script=COUNT_SOCKETS)
    try:
        assert tab.evaluate("window.__sockets.length") >= 1
        delays = tab.evaluate(
            "[0, 1, 2, 3, 4, 5, 10].map(a => window.skyhelm.reconnectDelayMs(a, () => 1))"
        )
        assert delays == [500, 1000, 2000, 4000, 8000, 15000, 15000]
        serve.stop()
        tab.wait_for_function(
            "document.getElementById('conn-status').textContent.startsWith('reconnecting')",
            timeout=10_000,
        )
        before = tab.evaluate("window.__sockets.length")

        def attempts() -> int:
            return int(tab.evaluate("window.__sockets.length")) - before

        # 0.5 s doubling to 15 s with full jitter: about 5 in 10 s (4 a second before)
        holds_for_blocking("at most 8 attempts", lambda: attempts() <= 8, 10.0, every_s=0.5)
        assert attempts() >= 1
        serve.restart()
        tab.wait_for_function(
            "document.getElementById('conn-status').textContent === 'connected'", timeout=60_000
        )
    finally:
        tab.close()


def test_a_rejected_token_shows_a_banner_and_stops_asking(browser: Any, serve: Serve) -> None:
    tab = browser.new_page()
    requests: list[str] = []
    tab.on("request", lambda r: requests.append(r.url) if "/api/v1/" in r.url else None)
    try:
        tab.add_init_script(COUNT_SOCKETS)
        tab.goto(f"{serve.base}/?token=not-the-token&scene=off")
        tab.wait_for_function(
            "document.getElementById('banner').textContent.includes('new link')", timeout=15_000
        )
        assert tab.text_content("#conn-status") == "token rejected"
        asked = len(requests)
        sockets = tab.evaluate("window.__sockets.length")
        holds_for_blocking(
            "no more requests or sockets",
            lambda: len(requests) == asked and tab.evaluate("window.__sockets.length") == sockets,
            3.0,
        )
        assert tab.is_visible("#banner")
    finally:
        tab.close()
