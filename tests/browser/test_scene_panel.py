"""The 3D view's own panel says what it shows, never viser's "Connected" (its socket to the
server, which a pilot reads as the vehicle), and names a vehicle whose link is lost."""

from __future__ import annotations

from typing import Any

from .flows import SCENE_START_MS, open_dashboard
from .harness import Serve, wait_for
from .pausing import sim_paused

SERVE_ARGS = ["--sim-speed", "2"]
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


# server/scene/pace.js: the scene's frames while nothing changes, after a change, when driven
PACE = "() => window.skyhelmScenePace"
CHANGE_DRAWN_MS = 1000  # paced: 33 ms; held, a frame would wait up to 10 s


def test_the_scene_rests_while_nothing_changes_and_draws_a_change_or_a_pilot_at_once(
        serve: Serve, browser: Any) -> None:
    page = open_dashboard(browser, serve.url, scene=True)
    try:
        page.frame_locator("#scene").get_by_text("3D view", exact=True).wait_for(
            timeout=SCENE_START_MS)
        scene = next(f for f in page.frames if "/scene/" in f.url)
        paced_from_ms = scene.evaluate("() => window.skyhelmScenePace.pacedFromMs")
        scene.wait_for_function(f"() => performance.now() > {paced_from_ms} + 500",
                                timeout=SCENE_START_MS)
        # landed, nothing changing: viser asks a frame a second; drawn at most every 10 s
        t0 = scene.evaluate("() => performance.now()")
        page.wait_for_timeout(4000)  # the window watched
        pace = scene.evaluate(PACE)
        unexplained = [f for f in pace["frameTimes"] if f > t0 and not any(
            0 <= f - m <= 600 for m in pace["messageTimes"])]
        assert len(unexplained) <= 1, pace
        # a change in the scene (the vehicle armed: its rotors' shade) is drawn at once
        seen = pace["messages"]
        with serve.client() as api:
            wait_for("ready to arm", lambda: api.get("/vehicles/1").json()["ready_to_arm"], 30.0)
            lease = api.post("/vehicles/1/control", json={"takeover": True, "force": True})
            headers = {"X-Lease-Id": lease.json()["lease_id"]}
            try:
                assert api.post("/vehicles/1/arm", json={}, headers=headers).status_code == 200
                scene.wait_for_function(f"() => window.skyhelmScenePace.messages > {seen}",
                                        timeout=15_000)
                page.wait_for_timeout(CHANGE_DRAWN_MS)
                api.post("/vehicles/1/disarm", json={}, headers=headers)
            finally:
                api.delete("/vehicles/1/control", headers=headers)
        page.wait_for_timeout(CHANGE_DRAWN_MS)  # the disarm's change its time to be drawn too
        pace = scene.evaluate(PACE)
        now_ms = scene.evaluate("() => performance.now()")
        # every change since the arm, but one that came within the last second: its frame
        # may still be due
        late = [m for m in pace["messageTimes"][-(pace["messages"] - seen):]
                if m < now_ms - CHANGE_DRAWN_MS
                and not any(0 <= f - m <= CHANGE_DRAWN_MS for f in pace["frameTimes"])]
        assert late == [], pace
        # the pilot drives the view: every frame asked for is drawn
        frames = pace["frames"]
        box = page.locator("#scene").bounding_box()
        assert box is not None
        page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.mouse.move(box["x"] + box["width"] / 3, box["y"] + box["height"] / 3, steps=5)
        scene.wait_for_function(f"() => window.skyhelmScenePace.frames >= {frames} + 2",
                                timeout=CHANGE_DRAWN_MS + 1500)
    finally:
        page.close()
