"""The page's layout in Chromium at 1280x800 and 1920x1080, light and dark: every visible
control and panel lies inside the window or inside the column that scrolls it, nothing is
clipped by a box that hides its overflow, no two controls overlap and no button's label is
cut; the shortcut list opens with '?'; the theme follows the system and the pilot's choice
is kept for the next visit."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from .harness import CHROMIUM

# A function the page evaluates: every visible control's and panel's box checked, a list of
# what is wrong.
LAYOUT_PROBLEMS = (Path(__file__).with_name("layout_probe.js")).read_text()

SIZES = [(1280, 800), (1920, 1080)]
THEMES = ["light", "dark"]


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


def _open(chromium: Any, url: str, size: tuple[int, int], scheme: str) -> Any:
    # the page's CSP forbids eval, which string predicates need; the tablet test keeps it
    context = chromium.new_context(
        viewport={"width": size[0], "height": size[1]}, color_scheme=scheme, bypass_csp=True
    )
    page = context.new_page()
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


@pytest.mark.parametrize("scheme", THEMES)
@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_no_control_is_cut_or_overlaps_another(
    chromium: Any, serve: Any, size: tuple[int, int], scheme: str
) -> None:
    page = _open(chromium, serve.url, size, scheme)
    try:
        assert page.evaluate("document.documentElement.dataset.theme") == scheme
        # the map alone (the 3D scene off, as the tests run it)
        assert _problems(page) == []
        # with every folded section open too
        page.evaluate("document.querySelectorAll('details').forEach((d) => { d.open = true; })")
        assert _problems(page) == []
        # the map and the 3D scene's box side by side, without starting its software WebGL
        page.evaluate("document.getElementById('views').classList.remove('no-scene')")
        scene_box = page.locator("#scene-view").bounding_box()
        assert scene_box is not None
        assert scene_box["width"] > 200
        assert _problems(page) == []
        # the shortcut list fits too
        page.keyboard.press("?")
        page.wait_for_selector("#shortcuts:not(.hidden)", timeout=5_000)
        box = page.locator("#shortcuts .overlay-box").bounding_box()
        assert box is not None
        assert box["y"] >= 0
        assert box["y"] + box["height"] <= size[1]
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
        assert _problems(page, page_may_scroll=True) == []
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
