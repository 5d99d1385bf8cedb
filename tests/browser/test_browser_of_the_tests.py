"""The tests' Chromium is the whole browser, headless: each page opens in a window with an
address bar, whose omnibox popup and AI mode panel Chromium loads as pages of their own
beside the test's page (a renderer's CPU at every page opened). The tests turn both off,
and their switch joins Playwright's own disabled features instead of replacing them
(Chromium keeps only its last --disable-features: tests/browser/chromium_for_tests.sh)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from .harness import CHROMIUM_TEST_ARGS
from .ordinary_priority import chromium_processes_of

DISABLED = "--disable-features="
# two of the features Playwright itself disables (it turns off the address bar's Lens and
# AI mode so that a headless browser does not ask Google for them)
PLAYWRIGHTS = {"LensOverlay", "AimEnabled"}
OURS = {"WebUIOmniboxPopup", "WebUIOmniboxAimPopup"}


def _browser_command_lines() -> list[list[str]]:
    """The command line of each Chromium browser process (not its children) this test
    process started."""
    found = []
    for pid in chromium_processes_of(os.getpid()):
        try:
            args = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
        except OSError:  # gone meanwhile
            continue
        if args[0].endswith("/chromium") and not any(a.startswith("--type=") for a in args):
            found.append(args)
    return found


def test_the_tests_switch_joins_playwrights_disabled_features(chromium: Any) -> None:
    assert any(arg.startswith(DISABLED) for arg in CHROMIUM_TEST_ARGS)
    browsers = _browser_command_lines()
    assert browsers, "no Chromium of the tests found running"
    for args in browsers:
        switches = [arg for arg in args if arg.startswith(DISABLED)]
        assert len(switches) == 1, switches
        disabled = set(switches[0].removeprefix(DISABLED).split(","))
        assert disabled >= PLAYWRIGHTS, sorted(disabled)
        assert disabled >= OURS, sorted(disabled)


def test_a_page_opens_without_the_address_bars_own_pages(chromium: Any) -> None:
    context = chromium.new_context()
    try:
        page = context.new_page()
        page.set_content("<p>a page</p>")
        session = chromium.new_browser_cdp_session()
        targets = session.send("Target.getTargets", {"filter": [{}]})["targetInfos"]
        session.detach()
    finally:
        context.close()
    shown = [(t["type"], t["url"]) for t in targets]
    assert ("page", "about:blank") in shown, shown
    assert not [url for kind, url in shown if kind == "browser_ui"], shown
