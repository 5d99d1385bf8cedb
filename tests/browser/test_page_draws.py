"""The page draws only what changed, as soon as it comes, and nothing while hidden: with a
landed vehicle whose state does not change, nothing on the page is written over a window
although states keep coming; a state is drawn within 100 ms of its arrival at the page's
socket; a hidden page (document.visibilityState, as a browser says it of a background tab)
draws nothing and catches up at once when shown again."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from .flows import settle_vehicle
from .harness import Serve

SERVE_ARGS = ["--sim-speed", "2"]
PAGE_TIMEOUT_MS = 20_000
# A window over which a landed vehicle's page is watched. The page asks for states on change
# (docs/api.md): a landed vehicle's come at least every ON_CHANGE_KEEPALIVE_S and a tick
# (0.6 s), so at least three in it.
QUIET_WINDOW_S = 2.0
QUIET_WINDOW_STATES = 3
DRAWN_WITHIN_MS = 100.0
HIDDEN_RATE_HZ = 1  # web/api.js

# Every state message for the selected vehicle, with its arrival time at the socket (this
# listener is the socket's first: it runs before the page's own handler).
STATE_ARRIVALS = """
window.__arrivals = [];
window.__linkQualities = [];
const PageSocket = window.WebSocket;
window.WebSocket = class extends PageSocket {
  constructor(url, ...rest) {
    super(url, ...rest);
    if (!String(url).includes("/ws/telemetry")) return;
    this.addEventListener("message", (event) => {
      const arrived = performance.now();
      const message = JSON.parse(event.data);
      if (message.type === "state" && message.vehicle === window.skyhelm?.page.vehicleId) {
        window.__arrivals.push(arrived);
        window.__linkQualities.push(JSON.stringify(message.link_quality));
      }
    });
  }
};
"""
WATCH_MUTATIONS = """
() => {
  window.__mutations = [];
  window.__watchStart = performance.now();
  window.__observer = new MutationObserver((records) => {
    for (const r of records) {
      const el = r.target.nodeType === 1 ? r.target : r.target.parentElement;
      const name = el?.id || el?.className || el?.tagName;
      window.__mutations.push(`${name} ${r.type} ${r.attributeName || ""}`);
    }
  });
  window.__observer.observe(document.body, {
    subtree: true, attributes: true, characterData: true, childList: true,
  });
}
"""
# How a browser tells a page it went to the background, and back (headless Chromium keeps
# every page "visible", so the property and the event are set as a browser sets them).
SET_VISIBILITY = """
(state) => {
  Object.defineProperty(document, "visibilityState", { configurable: true, get: () => state });
  Object.defineProperty(document, "hidden", { configurable: true, get: () => state === "hidden" });
  document.dispatchEvent(new Event("visibilitychange"));
}
"""


def _open(browser: Any, serve: Serve) -> Any:
    page = browser.new_page()
    page.add_init_script(STATE_ARRIVALS)
    page.goto(f"{serve.url}&scene=off")
    page.wait_for_function("document.getElementById('mode').textContent !== '–'",
                           timeout=PAGE_TIMEOUT_MS)
    return page


@pytest.fixture
def landed_page(api: httpx.Client, serve: Serve, browser: Any) -> Iterator[Any]:
    """A page of its own on the landed vehicle (whatever an earlier test left), closed after."""
    settle_vehicle(api, flying=False)
    page = _open(browser, serve)
    try:
        yield page
    finally:
        page.close()


def _arrivals(page: Any) -> int:
    count: int = page.evaluate("window.__arrivals.length")
    return count


def _watched(page: Any) -> tuple[list[str], float, int]:
    """What WATCH_MUTATIONS saw: the mutations, the seconds it watched and the states that
    came meanwhile, all by the page's own clock (a busy machine stretches the test's sleep
    and its calls to the page, so a window timed by the test is longer than it says)."""
    seen: dict[str, Any] = page.evaluate(
        "({mutations: window.__mutations,"
        " window_s: (performance.now() - window.__watchStart) / 1000,"
        " states: window.__arrivals.filter((t) => t >= window.__watchStart).length})"
    )
    return seen["mutations"], seen["window_s"], seen["states"]


def test_a_landed_vehicle_whose_state_does_not_change_writes_nothing_to_the_page(
    landed_page: Any,
) -> None:
    page = landed_page
    # the first states drawn, the ages settled
    page.wait_for_function("window.skyhelm.draws.state >= 10", timeout=PAGE_TIMEOUT_MS)
    page.evaluate(WATCH_MUTATIONS)
    came = _arrivals(page)
    time.sleep(QUIET_WINDOW_S)  # the window watched, not a wait for a condition
    mutations: list[str] = page.evaluate("window.__mutations")
    assert _arrivals(page) - came >= QUIET_WINDOW_STATES, "states kept coming over the window"
    # the link's measured frame loss is the one thing that may change on its own (a
    # frame lost on a busy machine): only then may the LINK box change
    qualities = set(page.evaluate(f"window.__linkQualities.slice({came - 1})"))
    if len(qualities) > 1:
        mutations = [m for m in mutations if not m.startswith(("link-loss ", "link-slot "))]
    assert mutations == [], mutations


def test_every_state_is_drawn_within_100_ms_of_its_arrival(landed_page: Any) -> None:
    page = landed_page
    page.wait_for_function("window.__arrivals.length >= 20", timeout=PAGE_TIMEOUT_MS)
    arrivals: list[float] = page.evaluate("window.__arrivals.slice(-18, -1)")
    drawn: list[float] = page.evaluate("window.skyhelm.drawTimes.state")
    late = []
    for arrived in arrivals:
        after = [t for t in drawn if t >= arrived]
        assert after, f"the state that came at {arrived:.0f} ms was never drawn"
        if after[0] - arrived > DRAWN_WITHIN_MS:
            late.append(round(after[0] - arrived))
    assert late == [], f"drawn later than {DRAWN_WITHIN_MS} ms after arrival: {late}"


def test_a_hidden_page_draws_nothing_and_catches_up_at_once_when_shown(landed_page: Any) -> None:
    page = landed_page
    page.wait_for_function("window.skyhelm.draws.state >= 5", timeout=PAGE_TIMEOUT_MS)
    page.evaluate(SET_VISIBILITY, "hidden")
    page.evaluate(WATCH_MUTATIONS)
    draws: dict[str, int] = page.evaluate("({...window.skyhelm.draws})")
    time.sleep(QUIET_WINDOW_S)  # the window watched while hidden
    mutations, window_s, states = _watched(page)
    # a hidden page asks for a state a second (and both sockets speak at the switch)
    assert 1 <= states <= window_s * HIDDEN_RATE_HZ + 2, (states, window_s)
    assert page.evaluate("({...window.skyhelm.draws})") == draws
    assert mutations == []
    # shown again: the newest state is drawn at once, before the next one comes
    shown_at: float = page.evaluate(
        f"() => {{ ({SET_VISIBILITY})('visible'); return performance.now(); }}"
    )
    page.wait_for_function(
        f"window.skyhelm.draws.state > {draws['state']}", timeout=PAGE_TIMEOUT_MS
    )
    first = min(t for t in page.evaluate("window.skyhelm.drawTimes.state") if t >= shown_at)
    assert first - shown_at <= DRAWN_WITHIN_MS
    # and states come at the visible page's rate again (on change, twice a second at least)
    came = _arrivals(page)
    page.wait_for_function(f"window.__arrivals.length >= {came + 8}", timeout=PAGE_TIMEOUT_MS)


# The setpoint stream's running counters (web/render.js): at most twice a second while on time.
STREAM_COUNTERS_HZ = 2
# Two parts drawn on the same beat are drawn one task after the other (two timers due at the
# same time): apart by the first one's draw.
SAME_BEAT_MS = 25.0
HOVER_ALTITUDE_M = 5.0


def test_the_streams_running_counters_are_drawn_at_their_own_pace_while_it_is_on_time(
    api: httpx.Client, serve: Serve, browser: Any
) -> None:
    settle_vehicle(api, flying=True, altitude=HOVER_ALTITUDE_M)
    taken = api.post("/vehicles/1/control", json={"takeover": True, "force": True})
    taken.raise_for_status()
    headers = {"X-Lease-Id": taken.json()["lease_id"]}
    page = None
    try:
        started = api.post("/vehicles/1/offboard/start", json={}, headers=headers)
        assert started.status_code == 200, started.text
        page = _open(browser, serve)
        page.wait_for_function(
            "document.getElementById('stream-active').textContent === 'streaming'",
            timeout=PAGE_TIMEOUT_MS)
        page.evaluate(WATCH_MUTATIONS)
        came = _arrivals(page)
        drawn = page.evaluate("window.skyhelm.draws.state")
        time.sleep(QUIET_WINDOW_S)  # the window watched, not a wait for a condition
        api.put("/vehicles/1/control", headers=headers).raise_for_status()  # renewed
        mutations, window_s, _ = _watched(page)
        states = _arrivals(page) - came
        # states kept coming and were drawn (the stream's figures change in every one)
        assert states >= 4 * QUIET_WINDOW_S * STREAM_COUNTERS_HZ, states
        assert page.evaluate("window.skyhelm.draws.state") - drawn >= states // 2
        sent = [m for m in mutations if m.startswith("stream-sent ")]
        # the count still follows the stream, at its own pace (+1: a draw at each end)
        most = window_s * STREAM_COUNTERS_HZ + 1
        assert 1 <= len(sent) <= most, (states, window_s, sent)
        assert sum(m.startswith("stream-since ") for m in mutations) <= most
        # on the plots' beat: both change in the same frames (the median, as a busy machine
        # may hold one task back; on their own the two would be apart by 0-250 ms)
        times: dict[str, list[float]] = page.evaluate(
            "({counters: window.skyhelm.drawTimes['stream-counters'],"
            " plots: window.skyhelm.drawTimes.plots})")
        apart = sorted(min(abs(t - p) for p in times["plots"]) for t in times["counters"])
        assert len(apart) >= 4
        assert apart[(len(apart) - 1) // 2] <= SAME_BEAT_MS, apart
    finally:
        if page is not None:
            page.close()
        api.post("/vehicles/1/offboard/stop", json={"then_mode": "HOLD"}, headers=headers)
        api.delete("/vehicles/1/control", headers=headers)


def test_the_map_unticked_draws_nothing_and_is_drawn_at_once_when_ticked_again(
    landed_page: Any,
) -> None:
    page = landed_page
    page.wait_for_function("window.skyhelm.draws.map >= 2", timeout=PAGE_TIMEOUT_MS)
    page.uncheck("#map-enable")
    page.wait_for_function("getComputedStyle(document.getElementById('map')).display"
                           " === 'none'", timeout=PAGE_TIMEOUT_MS)
    came = _arrivals(page) + 1
    page.wait_for_function(f"window.__arrivals.length >= {came}", timeout=PAGE_TIMEOUT_MS)
    drawn = page.evaluate("window.skyhelm.draws.map")  # the draw of a state on its way
    came = _arrivals(page)
    page.wait_for_function(f"window.__arrivals.length >= {came + 3}",
                           timeout=PAGE_TIMEOUT_MS)
    assert page.evaluate("window.skyhelm.draws.map") == drawn, "drawn while unticked"
    shown_at: float = page.evaluate(
        "() => { document.getElementById('map-enable').click(); return performance.now(); }")
    page.wait_for_function(f"window.skyhelm.draws.map > {drawn}", timeout=PAGE_TIMEOUT_MS)
    first = min(t for t in page.evaluate("window.skyhelm.drawTimes.map") if t >= shown_at)
    assert first - shown_at <= DRAWN_WITHIN_MS
