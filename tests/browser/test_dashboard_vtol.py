"""The VTOL transition buttons in Chromium against `skyhelm serve --sim-airframe vtol`."""

from __future__ import annotations

from typing import Any

import httpx

from .flows import arm_and_take_off, click_and_wait_result, take_control
from .harness import vehicle_state, wait_for

SERVE_ARGS = ["--sim-airframe", "vtol", "--sim-speed", "3"]


def test_transition_buttons_reach_fixed_wing_and_back(page: Any, api: httpx.Client) -> None:
    assert page.is_visible("#vtol-panel")
    take_control(page)
    arm_and_take_off(page, api, 20.0)
    assert vehicle_state(api)["vtol_state"] == "MC"

    def reached(target: str) -> bool:
        return bool(vehicle_state(api)["vtol_state"] == target)

    click_and_wait_result(page, "#btn-to-fw")
    wait_for("FW", lambda: reached("FW"), 30.0)
    page.wait_for_function(
        "document.getElementById('vtol-state').textContent === 'FW'", timeout=10_000
    )
    assert "100%" in (page.get_attribute("#vtol-progress-bar", "style") or "")

    click_and_wait_result(page, "#btn-to-mc")
    wait_for("MC", lambda: reached("MC"), 30.0)
    page.wait_for_function(
        "document.getElementById('vtol-state').textContent === 'MC'", timeout=10_000
    )
