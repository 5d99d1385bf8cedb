"""Alerts in Chromium against `skyhelm serve` and its simulated quad: the link-lost alert is
shown, dispatched as an event and spoken (speechSynthesis stubbed in the page to record what
it is asked to say) when the vehicle falls silent, and cleared when it talks again; a muted
tab (mute remembered across a reload) shows and records it without speaking; a tab whose
control is taken (after the taker confirmed) hears it."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import httpx

from .flows import open_dashboard, settle_vehicle, take_control
from .harness import Serve
from .pausing import sim_paused

SERVE_ARGS = ["--sim-speed", "2"]
PAGE_TIMEOUT_MS = 20_000

# Replaces the browser's speech with a recorder (headless Chromium has no voices), and
# records every alert event the page dispatches.
SPEECH_STUB = """
window.__spoken = [];
window.__alertEvents = [];
class StubUtterance { constructor(text) { this.text = text; } }
Object.defineProperty(window, "SpeechSynthesisUtterance", {
  value: StubUtterance, configurable: true,
});
Object.defineProperty(window, "speechSynthesis", {
  value: { speak: (u) => window.__spoken.push(u.text), cancel: () => {} }, configurable: true,
});
document.addEventListener("skyhelm-alert", (e) => window.__alertEvents.push(e.detail));
"""


def _events(page: Any, kind: str) -> list[dict[str, Any]]:
    events: list[dict[str, Any]] = page.evaluate(
        "(kind) => window.__alertEvents.filter((e) => e.kind === kind)", kind
    )
    return events


@contextmanager
def _two_recording_tabs(browser: Any, serve: Serve, api: httpx.Client) -> Iterator[tuple[Any, Any]]:
    """Two dashboard tabs on the settled vehicle, each recording its alerts and speech; a
    mute set in either is forgotten afterwards (the tabs share the page's storage)."""
    settle_vehicle(api, flying=False)
    first = open_dashboard(browser, serve.url, scene=False, init_script=SPEECH_STUB)
    second = open_dashboard(browser, serve.url, scene=False, init_script=SPEECH_STUB)
    try:
        yield first, second
    finally:
        second.evaluate("localStorage.removeItem('skyhelm.alerts.muted')")
        second.close()
        first.close()


def test_link_lost_is_shown_spoken_and_recorded_and_a_muted_tab_only_shows_it(
    browser: Any, serve: Serve, api: httpx.Client
) -> None:
    with _two_recording_tabs(browser, serve, api) as (loud, quiet):
        assert quiet.text_content("#alerts-mute") == "Sound: on"
        quiet.click("#alerts-mute")
        assert quiet.text_content("#alerts-mute") == "Sound: muted"
        quiet.reload()
        quiet.wait_for_function(
            "document.getElementById('mode').textContent !== '–'", timeout=PAGE_TIMEOUT_MS
        )
        assert quiet.text_content("#alerts-mute") == "Sound: muted"  # remembered
        assert _events(loud, "link") == []

        with sim_paused(serve):
            for page in (loud, quiet):
                page.wait_for_selector('.alert[data-kind="link"]', timeout=PAGE_TIMEOUT_MS)
            banner = loud.text_content('.alert[data-kind="link"] span') or ""
            # with how the server noticed: the sim's silence, its link's 1 s bound
            assert banner == "Link lost with vehicle 1 — nothing heard for 1.0 s", banner
            heard = _events(loud, "link")
            assert len(heard) == 1
            assert heard[0]["spoken"]
            assert heard[0]["level"] == "critical"
            assert loud.evaluate("window.__spoken") == [heard[0]["text"]]
            assert loud.evaluate("window.skyhelm.alertLog.map((a) => a.kind)") == ["link"]
            muted = _events(quiet, "link")
            assert len(muted) == 1
            assert not muted[0]["spoken"]
            assert quiet.evaluate("window.__spoken") == []

        for page in (loud, quiet):
            page.wait_for_selector('.alert[data-kind="link"]', state="detached",
                                   timeout=PAGE_TIMEOUT_MS)  # fmt: skip
        loud.wait_for_selector('.alert[data-kind="link-back"]', timeout=PAGE_TIMEOUT_MS)
        assert len(_events(loud, "link")) == 1  # said once, not at every state


def test_a_tab_hears_that_its_control_was_taken_after_the_taker_confirmed(
    browser: Any, serve: Serve, api: httpx.Client
) -> None:
    with _two_recording_tabs(browser, serve, api) as (pilot, taker):
        take_control(pilot)
        taker.wait_for_selector("#force-control:not(.hidden)", timeout=PAGE_TIMEOUT_MS)
        taker.click("#force-control")
        assert taker.text_content("#force-control") == "Sure?"
        assert _events(pilot, "control") == []  # one click takes nothing

        taker.click("#force-control")
        pilot.wait_for_selector('.alert[data-kind="control"]', timeout=PAGE_TIMEOUT_MS)
        heard = _events(pilot, "control")
        assert len(heard) == 1
        assert heard[0]["text"].startswith("Control taken by ")
        assert pilot.evaluate("window.__spoken") == [heard[0]["text"]]
        assert _events(taker, "control") == []
