"""Ready to fly in the top bar, in Chromium against `skyhelm serve` with the simulated quad:
"Ready to fly" once PX4's checks pass, "Not ready" with PX4's reason in the popover when the
mode flown cannot arm, and the element's box the same in every state."""

from __future__ import annotations

from typing import Any

import httpx

from .flows import (
    click_and_wait_result,
    settle_vehicle,
    start_offboard_here,
    take_control,
    wait_for_text,
)
from .harness import vehicle_state, wait_for

SERVE_ARGS = ["--sim-speed", "3"]
READY = "#ready-to-fly"


def _shows(page: Any, text: str) -> None:
    page.wait_for_function(
        "([sel, text]) => document.querySelector(sel).textContent === text",
        arg=[READY, text], timeout=20_000,
    )  # fmt: skip


def _box(page: Any) -> tuple[float, float]:
    box = page.locator(READY).bounding_box()
    return round(box["width"], 1), round(box["height"], 1)


def _set_mode(page: Any, mode: str) -> None:
    page.select_option("#mode-select", mode)
    click_and_wait_result(page, "#btn-set-mode")


def test_ready_then_not_ready_with_px4s_reason_for_the_mode_flown(
    page: Any, api: httpx.Client
) -> None:
    settle_vehicle(api, flying=False)
    _shows(page, "Ready to fly")
    assert "ok" in (page.get_attribute(READY, "class") or "")
    ready_box = _box(page)
    take_control(page)

    # disarmed, no setpoint stream: PX4 would refuse to arm in OFFBOARD, for that mode's own
    # check only, and SkyHelm's Arm switches to HOLD first: amber, not red
    _set_mode(page, "OFFBOARD")
    page.wait_for_function(
        "document.getElementById('ready-to-fly').classList.contains('warn')", timeout=20_000
    )
    assert _box(page) == ready_box
    page.click(READY)
    popover = page.locator("#ready-popover")
    popover.wait_for(state="visible", timeout=5_000)
    text = popover.text_content() or ""
    assert "In OFFBOARD (flown): cannot arm" in text
    assert "No offboard signal" in text
    assert page.get_attribute(READY, "aria-expanded") == "true"
    # the mode picked in the menu gets its own verdict
    page.select_option("#mode-select", "HOLD")
    page.wait_for_function(
        "document.getElementById('ready-popover').textContent"
        ".includes('In HOLD (picked): can arm')",
        timeout=5_000,
    )
    page.keyboard.press("Escape")
    popover.wait_for(state="hidden", timeout=5_000)

    # MISSION without a mission: PX4 refuses, and Arm arms in the mode flown: red
    _set_mode(page, "MISSION")
    _shows(page, "Not ready")
    assert "bad" in (page.get_attribute(READY, "class") or "")
    assert _box(page) == ready_box

    _set_mode(page, "HOLD")
    _shows(page, "Ready to fly")
    assert _box(page) == ready_box


def test_after_a_landing_amber_arm_switches_to_hold_first_and_arming_works(
    page: Any, api: httpx.Client
) -> None:
    settle_vehicle(api, flying=True)
    take_control(page)
    start_offboard_here(page, api)
    click_and_wait_result(page, "#btn-land")
    wait_for(
        "landed and disarmed",
        lambda: not (s := vehicle_state(api))["armed"] and s["landed_state"] == "ON_GROUND",
        90.0,
    )
    # PX4 sits in LAND (or back in the pilot's OFFBOARD): it would not arm there, but
    # SkyHelm's Arm switches to HOLD first, so the badge says what to do, in amber
    page.wait_for_function(
        "document.getElementById('ready-to-fly').classList.contains('warn')", timeout=20_000
    )
    assert (page.text_content(READY) or "").startswith("Ready")
    label = page.get_attribute(READY, "aria-label") or ""
    assert label == "Ready — Arm switches to Hold first", label
    assert "Arm → Hold first" in (page.text_content(READY) or "")
    assert vehicle_state(api)["mode"] in ("LAND", "OFFBOARD")
    page.click(READY)
    popover = page.locator("#ready-popover")
    popover.wait_for(state="visible", timeout=5_000)
    assert "Arm (and Takeoff) switch to HOLD first" in (popover.text_content() or "")
    page.keyboard.press("Escape")

    click_and_wait_result(page, "#btn-arm", confirm=True)
    state = wait_for("armed", lambda: (s := vehicle_state(api))["armed"] and s, 10.0)
    assert state["mode"] == "HOLD"
    _shows(page, "Armed")
    click_and_wait_result(page, "#btn-disarm", confirm=True)


def test_picked_modes_px4_will_not_arm_in_say_so(page: Any, api: httpx.Client) -> None:
    settle_vehicle(api, flying=False)
    _shows(page, "Ready to fly")
    take_control(page)
    page.click(READY)
    for mode in ("LAND", "RTL"):
        page.select_option("#mode-select", mode)
        wait_for_text(page, "ready-popover", f"In {mode} (picked): cannot arm")
        assert "Mode not suitable for arming" in (page.text_content("#ready-popover") or "")
    page.keyboard.press("Escape")


# PX4 v1.16 in RTL on the ground, as a server that has not read PX4's events metadata yet
# (the first seconds after it connects) reports it: SYS_STATUS's pre-arm bit clear, no
# sensor unhealthy, so no reason in PX4's words yet.
SYS_STATUS_ONLY = {
    "armed": False,
    "arming_checks": {
        "ready": False, "mode": "RTL", "source": "sys_status", "can_arm_modes": [],
        "reasons": [], "other_reasons": [], "verdict": "not_ready", "arm_switches_to": None,
        "waiting_for": [],
    },
}


def test_not_ready_from_sys_status_alone_never_says_no_check_fails(page: Any) -> None:
    """PX4 says it cannot arm (SYS_STATUS's pre-arm bit) before its reasons can be read: the
    popover says so, not "No check fails" under "cannot arm"."""
    text = page.evaluate(
        """async (state) => {
          const { readiness } = await import('./readiness.js');
          readiness.toggle(true);
          readiness.show(state);  // at once, before the next state from the server
          const text = document.getElementById('ready-popover').textContent;
          readiness.toggle(false);
          return text;
        }""",
        SYS_STATUS_ONLY,
    )
    assert "In RTL (flown): cannot arm" in text
    assert "No check fails" not in text
    assert "PX4 reports it cannot arm in RTL (SYS_STATUS's pre-arm check)" in text
