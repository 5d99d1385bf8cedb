"""The map with two simulated vehicles: both drawn from the start, each where the API says
it is, and a click on the other one selects it for the whole page."""

from __future__ import annotations

from typing import Any

import httpx

from .harness import vehicle_state, wait_for

SERVE_ARGS = ["--sim-count", "2"]


def _marker_centre(page: Any, vehicle_id: int) -> tuple[float, float]:
    box = page.locator(".map-vehicle", has_text=str(vehicle_id)).bounding_box()
    assert box is not None
    return box["x"] + box["width"] / 2, box["y"] + box["height"] / 2


def test_map_shows_every_vehicle_and_a_click_on_one_selects_it(
    page: Any, api: httpx.Client
) -> None:
    wait_for("two vehicles", lambda: len(api.get("/vehicles").json()) == 2, 30.0)
    page.wait_for_function("document.querySelectorAll('.map-vehicle').length === 2", timeout=30_000)
    assert page.input_value("#vehicle-select") == "1"
    for vehicle_id in (1, 2):
        position = vehicle_state(api, vehicle_id)["global"]
        point = page.evaluate(
            "([lat, lon]) => window.skyhelm.map.pagePoint(lat, lon)",
            [position["lat_deg"], position["lon_deg"]],
        )
        x, y = _marker_centre(page, vehicle_id)
        assert abs(x - point["x"]) < 4
        assert abs(y - point["y"]) < 4
    selected = page.locator(".map-vehicle.selected")
    assert selected.count() == 1
    assert "1" in (selected.text_content() or "")
    # the simulated vehicles stand 2 m apart: close in on the other one, then click it
    position = vehicle_state(api, 2)["global"]
    page.evaluate(
        "([lat, lon]) => window.skyhelm.map.map.setView([lat, lon], 22, {animate: false})",
        [position["lat_deg"], position["lon_deg"]],
    )
    page.mouse.click(*_marker_centre(page, 2))
    page.wait_for_function(
        "document.getElementById('vehicle-select').value === '2'", timeout=10_000
    )
    page.wait_for_function("window.skyhelm.page.state?.sysid === 2", timeout=10_000)
    assert "2" in (page.locator(".map-vehicle.selected").text_content() or "")
