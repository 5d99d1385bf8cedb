"""Ready to fly in the top bar, in Chromium against `skyhelm serve` with the simulated quad:
"Ready to fly" once PX4's checks pass, "Not ready" with PX4's reason in the popover when the
mode flown cannot arm, and the element's box the same in every state."""

from __future__ import annotations

from typing import Any

import httpx

from .flows import click_and_wait_result, settle_vehicle, take_control

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

    _set_mode(page, "OFFBOARD")  # disarmed, no setpoint stream: PX4 would refuse to arm
    _shows(page, "Not ready")
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

    _set_mode(page, "HOLD")
    _shows(page, "Ready to fly")
    assert _box(page) == ready_box
