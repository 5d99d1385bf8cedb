"""A server without the 3D scene (`skyhelm serve --no-scene`): the page asks nothing of
/scene/ (no 404 in the console) and says the view is not there, with the 3D box ticked."""

from __future__ import annotations

from typing import Any
from urllib.parse import urlparse

from .harness import Serve

SERVE_ARGS = ["--no-scene", "--sim-speed", "2"]
PAGE_TIMEOUT_MS = 20_000


def test_the_page_asks_nothing_of_the_scene_without_one(serve: Serve, browser: Any) -> None:
    page = browser.new_page()
    asked: list[str] = []
    failed: list[str] = []
    errors: list[str] = []
    page.on("request", lambda r: asked.append(urlparse(r.url).path))
    page.on("response", lambda r: failed.append(r.url) if r.status >= 400 else None)
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    try:
        page.goto(serve.url)  # the 3D box ticked, as by default
        page.wait_for_function("document.getElementById('mode').textContent !== '–'",
                               timeout=PAGE_TIMEOUT_MS)
        page.wait_for_function("window.skyhelm.page.sceneServed === false",
                               timeout=PAGE_TIMEOUT_MS)
        assert page.is_checked("#scene-enable")
        assert page.is_hidden("#scene")
        assert "no 3D scene" in (page.text_content("#scene-off") or "")
        # the box unticked and ticked again asks nothing either
        page.uncheck("#scene-enable")
        page.check("#scene-enable")
        assert page.is_hidden("#scene")
        assert [path for path in asked if path.startswith("/scene/") or path == "/scene"] == []
        assert failed == [], failed
        assert errors == [], errors
    finally:
        page.close()
