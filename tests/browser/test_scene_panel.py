"""The 3D view's own panel says what it shows, never viser's "Connected" (its socket to the
server, which a pilot reads as the vehicle), and names a vehicle whose link is lost."""

from __future__ import annotations

from typing import Any

from .flows import open_dashboard
from .harness import Serve
from .pausing import sim_paused

SERVE_ARGS = ["--sim-speed", "2"]
SCENE_START_MS = 60_000  # software WebGL starts viser's client slowly
LINK_VERDICT_MS = 30_000


def test_the_scene_panel_names_the_view_and_a_lost_link(serve: Serve, browser: Any) -> None:
    page = open_dashboard(browser, serve.url, scene=True)
    try:
        scene = page.frame_locator("#scene")
        scene.get_by_text("3D view", exact=True).wait_for(timeout=SCENE_START_MS)
        assert scene.get_by_text("Connected", exact=True).count() == 0
        with sim_paused(serve):
            scene.get_by_text("3D view · link lost: vehicle 1", exact=True).wait_for(
                timeout=LINK_VERDICT_MS)
            assert scene.get_by_text("Connected", exact=True).count() == 0
        scene.get_by_text("3D view", exact=True).wait_for(timeout=LINK_VERDICT_MS)
    finally:
        page.close()
