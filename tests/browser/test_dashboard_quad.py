"""The dashboard in Chromium against `skyhelm serve` with the simulated quad: one server for
the module; the tests run in order as one flight."""

from __future__ import annotations

import io
import math
import time
from collections.abc import Iterator
from typing import Any

import httpx
import numpy as np
import pytest

from .flows import (
    arm_and_take_off,
    click_and_wait_result,
    drag_slider_to,
    open_dashboard,
    take_control,
)
from .harness import Serve, altitude_m, empty_scene, speed_m_s, vehicle_state, wait_for

SIM_SPEED = "3"


@pytest.fixture(scope="module")
def serve() -> Iterator[Serve]:
    server = Serve(extra_args=["--sim-speed", SIM_SPEED])
    server.start()
    try:
        yield server
    finally:
        server.stop()
        server.discard_log()


@pytest.fixture(scope="module")
def api(serve: Serve) -> Iterator[httpx.Client]:
    with serve.client() as client:
        yield client


@pytest.fixture(scope="module")
def page(browser: Any, serve: Serve) -> Iterator[Any]:
    page = open_dashboard(browser, serve.url)
    yield page
    if not page.is_closed():
        page.close()


def _scene_frame(page: Any) -> Any:
    frame = page.frame_locator("#scene")
    frame.locator("canvas").first.wait_for(timeout=30_000)
    return frame


def _changed_pixels(a: bytes, b: bytes) -> int:
    from PIL import Image

    first = np.asarray(Image.open(io.BytesIO(a)).convert("RGB"), dtype=np.int16)
    second_image = Image.open(io.BytesIO(b)).convert("RGB").resize((first.shape[1], first.shape[0]))
    second = np.asarray(second_image, dtype=np.int16)
    return int((np.abs(first - second).max(axis=2) > 40).sum())


def test_page_shows_the_vehicle_and_observes_until_control_is_taken(page: Any) -> None:
    assert page.text_content("#conn-status") == "connected"
    assert page.text_content("#armed") == "DISARMED"
    assert "QUADROTOR" in (page.text_content("#vehicle-select") or "")
    assert page.is_disabled("#btn-arm")
    assert page.is_disabled("#btn-takeoff")
    assert page.is_visible("#take-control")
    modes = page.eval_on_selector_all("#mode-select option", "os => os.map(o => o.value)")
    for mode in ("MANUAL", "ALTCTL", "POSCTL", "OFFBOARD", "HOLD", "TAKEOFF", "LAND", "RTL",
                 "MISSION", "STABILIZED", "ACRO"):
        assert mode in modes


def test_scene_draws_the_vehicle_through_the_proxied_socket(page: Any, serve: Serve,
                                                            browser: Any) -> None:
    frame = _scene_frame(page)
    status = wait_for(
        "the viser client connected through the proxy",
        lambda: (s := httpx.get(f"{serve.base}/scene/api/status",
                                params={"token": serve.token}).json())["proxied_sockets"] >= 1
        and s["viser_clients"] >= 1 and s,
        20.0,
    )
    assert status["vehicles"] == [1]
    page.wait_for_timeout(1500)
    with_vehicle = frame.locator("canvas").first.screenshot()
    with empty_scene() as (base, token):
        other = browser.new_page()
        other.set_viewport_size(page.viewport_size)
        other.set_content(
            f'<iframe src="{base}/scene/?token={token}&darkMode" '
            'style="border:0;width:100%;height:100%;position:fixed;inset:0"></iframe>'
        )
        box = page.locator("#scene").bounding_box()
        other.locator("iframe").evaluate(
            f"(f) => {{ f.style.width='{box['width']}px'; f.style.height='{box['height']}px'; }}"
        )
        empty_canvas = other.frame_locator("iframe").locator("canvas").first
        empty_canvas.wait_for(timeout=30_000)
        other.wait_for_timeout(2000)
        empty = empty_canvas.screenshot()
        other.close()
    assert _changed_pixels(with_vehicle, empty) > 200


def test_click_in_the_scene_fills_the_reposition_target(page: Any) -> None:
    box = page.locator("#scene").bounding_box()
    # Below the centre, where the camera looks down at the ground grid. Mouse events go
    # straight to the canvas: software WebGL is too slow for Playwright's stability checks.
    page.mouse.click(box["x"] + box["width"] * 0.5, box["y"] + box["height"] * 0.8)
    page.wait_for_selector("#scene-click:not(.hidden)", timeout=20_000)
    assert "clicked" in (page.text_content("#scene-click") or "")
    lat = float(page.input_value("#repo-lat"))
    lon = float(page.input_value("#repo-lon"))
    state_global = page.evaluate("window.skyhelm.page.state.global")
    assert abs(lat - state_global["lat_deg"]) < 0.001
    assert abs(lon - state_global["lon_deg"]) < 0.001
    page.uncheck("#scene-enable")  # the rest of the flight needs no WebGL
    assert page.is_hidden("#scene")


def test_take_control_arm_and_take_off_by_clicking(page: Any, api: httpx.Client) -> None:
    take_control(page)
    assert api.get("/vehicles/1").json()["lease"]["holder"]
    arm_and_take_off(page, api, 5.0)
    assert vehicle_state(api)["armed"]
    log = page.text_content("#log") or ""
    assert "Arm: ACCEPTED" in log
    assert "Takeoff: ACCEPTED" in log
    assert page.text_content("#armed") == "ARMED"


def test_parameter_panel_writes_and_shows_the_vehicles_echo(page: Any,
                                                              api: httpx.Client) -> None:
    page.fill("#param-input-RTL_LAND_DELAY", "1")
    click_and_wait_result(page, "#param-set-RTL_LAND_DELAY", expect="= 1")
    assert page.text_content("#param-RTL_LAND_DELAY") == "1"
    assert api.get("/vehicles/1/params/RTL_LAND_DELAY").json()["value"] == 1
    page.fill("#param-input-RTL_LAND_DELAY", "0")
    click_and_wait_result(page, "#param-set-RTL_LAND_DELAY", expect="= 0")


def test_refused_command_shows_the_vehicles_reason(page: Any) -> None:
    text = click_and_wait_result(page, "#btn-disarm", expect="Disarm", confirm=True)
    assert "ACCEPTED" not in text
    assert "not landed" in text.lower() or "denied" in text.lower(), text
    assert "bad" in (page.get_attribute("#result", "class") or "")


def test_start_offboard_then_altitude_slider_moves_the_vehicle(page: Any,
                                                               api: httpx.Client) -> None:
    page.select_option("#sp-type", "position")
    page.click("#sp-from-here")
    click_and_wait_result(page, "#btn-offboard-start")
    wait_for("OFFBOARD", lambda: vehicle_state(api)["mode"] == "OFFBOARD", 10.0)
    target = drag_slider_to(page, "#sp-alt_m-slider", 9.0)
    assert 8.0 <= target <= 10.0
    assert float(page.input_value("#sp-alt_m")) == pytest.approx(target)
    wait_for(f"altitude within 0.5 m of the slider's {target} m",
             lambda: abs(altitude_m(vehicle_state(api)) - target) < 0.5, 30.0)
    assert page.text_content("#stream-active") == "streaming"
    assert "Hz" in (page.text_content("#stream-rate") or "")
    assert "ms" in (page.text_content("#stream-p99") or "")


def test_keyboard_velocity_moves_the_vehicle_and_space_holds_it(page: Any,
                                                                api: httpx.Client) -> None:
    start = vehicle_state(api)["position_ned"]
    page.click("#kbd-state")  # focus off the form fields, as a pilot would
    page.keyboard.down("w")
    wait_for("forward speed above 1 m/s", lambda: speed_m_s(vehicle_state(api)) > 1.0, 15.0)
    page.wait_for_timeout(500)
    page.keyboard.press("Space")
    page.keyboard.up("w")
    moved = vehicle_state(api)["position_ned"]
    assert math.hypot(moved["north_m"] - start["north_m"], moved["east_m"] - start["east_m"]) > 1.0
    held = wait_for(
        "a position hold with the vehicle stopped",
        lambda: (s := vehicle_state(api))["setpoint"]["type"] == "position_ned"
        and speed_m_s(s) < 0.3 and s, 15.0)
    assert held["mode"] == "OFFBOARD"
    time.sleep(1.0)
    later = vehicle_state(api)["position_ned"]
    assert math.hypot(later["north_m"] - held["position_ned"]["north_m"],
                      later["east_m"] - held["position_ned"]["east_m"]) < 0.5


def test_reposition_by_offset_from_the_form(page: Any, api: httpx.Client) -> None:
    before = vehicle_state(api)["position_ned"]
    page.fill("#repo-north", "8")
    page.fill("#repo-east", "-4")
    page.fill("#repo-alt", "7")
    click_and_wait_result(page, "#btn-repo-offset")
    wait_for("HOLD", lambda: vehicle_state(api)["mode"] == "HOLD", 10.0)

    def arrived() -> bool:
        s = vehicle_state(api)
        p = s["position_ned"]
        return (math.hypot(p["north_m"] - before["north_m"] - 8, p["east_m"] - before["east_m"] + 4)
                < 1.0 and abs(altitude_m(s) - 7.0) < 0.7)

    wait_for("arrival 8 m north, 4 m west, at 7 m", arrived, 30.0)


def test_return_lands_and_disarms(page: Any, api: httpx.Client) -> None:
    click_and_wait_result(page, "#btn-rtl")
    wait_for("landed and disarmed",
             lambda: (s := vehicle_state(api))["landed_state"] == "ON_GROUND" and not s["armed"],
             60.0, every_s=0.25)
    page.wait_for_function("document.getElementById('armed').textContent === 'DISARMED'",
                           timeout=10_000)
    home = vehicle_state(api)["home"]
    p = vehicle_state(api)["position_ned"]
    assert math.hypot(p["north_m"] - home["north_m"], p["east_m"] - home["east_m"]) < 1.5


def test_closing_the_page_triggers_the_deadman_hold(browser: Any, serve: Serve, page: Any,
                                                    api: httpx.Client) -> None:
    if page.is_visible("#release"):
        page.click("#release")
    page.wait_for_selector("#take-control:not(.hidden)")
    pilot = open_dashboard(browser, serve.url, scene=False)
    take_control(pilot)
    arm_and_take_off(pilot, api, 4.0)
    pilot.select_option("#sp-type", "velocity")
    click_and_wait_result(pilot, "#btn-offboard-start")
    pilot.fill("#sp-north_m_s", "2")
    pilot.dispatch_event("#sp-north_m_s", "input")
    wait_for("flying north at > 1.5 m/s", lambda: speed_m_s(vehicle_state(api)) > 1.5, 15.0)
    pilot.close()
    closed_at = time.monotonic()
    wait_for("the deadman's hold (speed < 0.3 m/s)",
             lambda: speed_m_s(vehicle_state(api)) < 0.3, 10.0, every_s=0.05)
    # TTL (2 s) + 0.5 s, in wall time, plus the sim's braking and this machine's noise.
    assert time.monotonic() - closed_at < 6.0
    state = vehicle_state(api)
    assert state["mode"] == "OFFBOARD"
    assert state["lease"]["holder"] is None


def test_page_reconnects_after_a_server_restart_and_takes_control_again(
        page: Any, serve: Serve) -> None:
    take_control(page)
    serve.restart()
    page.wait_for_function(
        "document.getElementById('conn-status').textContent === 'connected'"
        " && document.getElementById('log').textContent.includes('reconnected')",
        timeout=60_000,
    )
    page.wait_for_function("document.getElementById('mode').textContent !== '–'",
                           timeout=30_000)
    assert "connected" in (page.text_content("#conn-status") or "")
    page.wait_for_selector("#release:not(.hidden)", timeout=30_000)
    with serve.client() as api:
        assert wait_for("the lease held again",
                        lambda: api.get("/vehicles/1/control").json().get("holder"), 15.0)
