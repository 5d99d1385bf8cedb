"""Setpoints that mean what they show, in Chromium against `skyhelm serve` with the simulated
quad: the offboard form's North / East / Altitude / Yaw follow the vehicle until the pilot
edits one (each says "following" or "edited"), the panel says the move from where the
vehicle is now, and a target that would take an airborne vehicle low or change its altitude
by more than a few metres is asked about first, the same for the panel and the offsets."""

from __future__ import annotations

import re
from typing import Any

import httpx

from .flows import (
    arm_and_take_off,
    click_and_wait_result,
    settle_vehicle,
    take_control,
    wait_for_text,
)
from .harness import altitude_m, speed_m_s, vehicle_state, wait_for

SERVE_ARGS = ["--sim-speed", "2"]
TAKEOFF_M = 5.0
# the altitude the vehicle must keep while it flies north from the form
ALTITUDE_TOLERANCE_M = 0.5


def _value(page: Any, key: str) -> float:
    return float(page.input_value(f"#sp-{key}"))


def _tag(page: Any, key: str) -> str:
    return page.text_content(f"#sp-{key}-tag") or ""


def _dialog_open(page: Any) -> bool:
    return bool(page.evaluate("document.getElementById('confirm-dialog').open"))


def test_the_form_follows_the_vehicle_so_a_leg_north_keeps_the_altitude(
    page: Any, api: httpx.Client
) -> None:
    settle_vehicle(api, flying=False)
    # control taken on the ground: the form holds the vehicle's altitude then, 0 m
    take_control(page)
    assert _value(page, "alt_m") < 0.5
    assert _tag(page, "alt_m") == "following"
    assert (page.text_content("#sp-follow") or "") == "following the vehicle"

    arm_and_take_off(page, api, TAKEOFF_M)
    hover = wait_for(
        "hovering in HOLD",
        lambda: (s := vehicle_state(api))["mode"] == "HOLD" and speed_m_s(s) < 0.2 and s,
        30.0,
    )
    assert abs(altitude_m(hover) - TAKEOFF_M) < 0.3, altitude_m(hover)
    # the form followed the vehicle up: its altitude, not the 0 m it showed on the ground
    page.wait_for_function(
        "(alt) => Math.abs(parseFloat(document.getElementById('sp-alt_m').value) - alt) < 0.3",
        arg=altitude_m(hover), timeout=10_000,
    )  # fmt: skip
    north_now = hover["position_ned"]["north_m"]

    page.fill("#sp-north_m", "10")
    assert _tag(page, "north_m") == "edited"
    assert _tag(page, "alt_m") == "following"
    assert (page.text_content("#sp-follow") or "") == "edited"
    leg = round(10 - north_now, 1)
    said = page.text_content("#sp-move-text") or ""
    move = re.fullmatch(r"north \+([\d.]+) m, east 0 m, up 0 m", said)
    assert move, said
    assert abs(float(move.group(1)) - leg) <= 0.2, (move.group(0), leg)

    click_and_wait_result(page, "#btn-offboard-start")
    lowest, highest = TAKEOFF_M, TAKEOFF_M

    def arrived() -> bool:
        nonlocal lowest, highest
        state = vehicle_state(api)
        alt = altitude_m(state)
        lowest, highest = min(lowest, alt), max(highest, alt)
        return abs(state["position_ned"]["north_m"] - 10) < 0.5 and speed_m_s(state) < 0.3

    wait_for("at 10 m north", arrived, 40.0, every_s=0.05)
    assert vehicle_state(api)["mode"] == "OFFBOARD"
    print(f"leg north from {north_now:.1f} m: altitude {lowest:.2f}..{highest:.2f} m")  # with -s
    assert lowest >= TAKEOFF_M - ALTITUDE_TOLERANCE_M, f"sank to {lowest:.2f} m"
    assert highest <= TAKEOFF_M + ALTITUDE_TOLERANCE_M, f"rose to {highest:.2f} m"

    # Altitude 0 while airborne: nothing is sent before the pilot answers, with the numbers
    flown_down = vehicle_state(api)["setpoint"]["down_m"]
    # while the field is edited, its note names the altitude it shows now
    for typed in ("1", "0"):
        page.fill("#sp-alt_m", typed)
        wait_for_text(page, "result", f"Descend to {typed} m above home? — asked when you leave",
                      starts=True)
    page.press("#sp-alt_m", "Tab")
    page.wait_for_function("document.getElementById('confirm-dialog').open", timeout=5_000)
    question = page.text_content("#confirm-text") or ""
    assert "to 0 m" in question, question
    assert "below the safe 2 m above home" in question, question
    assert f"at {round(altitude_m(vehicle_state(api)), 1):g} m" in question or "at 5" in question
    assert vehicle_state(api)["setpoint"]["down_m"] == flown_down
    page.click("#confirm-cancel")
    assert not _dialog_open(page)
    assert page.text_content("#result") == "Descend to 0 m above home: cancelled"
    # cancelled: the altitude follows the vehicle again, and the vehicle never went down
    page.wait_for_function(
        "Math.abs(parseFloat(document.getElementById('sp-alt_m').value) - 5) < 0.5",
        timeout=5_000,
    )
    assert _tag(page, "alt_m") == "following"
    assert vehicle_state(api)["setpoint"]["down_m"] == flown_down
    assert abs(altitude_m(vehicle_state(api)) - TAKEOFF_M) <= ALTITUDE_TOLERANCE_M

    # the same rule for the offsets: 4 m down at once is asked about
    page.fill("#repo-up", "-4")
    page.click("#btn-repo-offset")
    page.wait_for_function("document.getElementById('confirm-dialog').open", timeout=5_000)
    assert "down 4" in (page.text_content("#confirm-text") or "")
    page.click("#confirm-cancel")
    page.wait_for_function(
        "document.getElementById('result').textContent.includes('cancelled')", timeout=5_000
    )
    assert vehicle_state(api)["mode"] == "OFFBOARD"
    page.fill("#repo-up", "0")

    # Follow: every field follows the vehicle again
    page.click("#sp-from-here")
    assert _tag(page, "north_m") == "following"
    assert (page.text_content("#sp-follow") or "") == "following the vehicle"

    # 4 m up at once, asked and confirmed: sent, and the note says so
    page.fill("#sp-alt_m", str(TAKEOFF_M + 4))
    page.press("#sp-alt_m", "Tab")
    page.wait_for_function("document.getElementById('confirm-dialog').open", timeout=5_000)
    page.click("#confirm-ok")
    wait_for("the climb sent", lambda: vehicle_state(api)["setpoint"]["down_m"] < -TAKEOFF_M - 3.5,
             5.0)
    assert page.text_content("#result") == f"Climb to {TAKEOFF_M + 4:g} m above home: confirmed"
    click_and_wait_result(page, "#btn-offboard-stop")
