"""The offboard panel's sliders in Chromium at 1280x800: each visible slider is wide (the row
gives it the panel's free width) and a position slider spans a window around the vehicle, so a
pixel is a fraction of a metre; the window follows the setpoint flown, re-centres when a value
nears an end, and the number box still takes any value the API accepts."""

from __future__ import annotations

from typing import Any

import httpx
import pytest

from .flows import drag_slider_to, settle_vehicle, start_offboard_here, take_control
from .harness import Serve, vehicle_state, wait_for

SERVE_ARGS = ["--sim-speed", "3"]
SIZE = {"width": 1280, "height": 800}
PANEL_TYPES = ["position", "velocity", "velocity_body", "alt_hold_velocity", "attitude"]
# Chromium's range thumb: its centre travels the slider's width minus this.
THUMB_PX = 16.0
MIN_SLIDER_PX = 200.0
MAX_POSITION_M_PER_PX = 0.25

# Every visible slider of the offboard panel: its box, range and unit.
SLIDERS = """() => [...document.querySelectorAll('#sp-fields input[type=range]')]
  .filter((el) => el.checkVisibility())
  .map((el) => {
    const box = el.getBoundingClientRect();
    const row = el.closest('.sp-field').getBoundingClientRect();
    return {
      id: el.id, width: box.width, rowWidth: row.width, min: Number(el.min),
      max: Number(el.max), value: Number(el.value),
      unit: el.closest('.sp-field').querySelector('.unit').textContent,
    };
  })"""


@pytest.fixture
def small_page(page: Any) -> Any:
    """The test's dashboard in a 1280x800 window."""
    page.set_viewport_size(SIZE)
    return page


@pytest.fixture
def on_ground(api: httpx.Client) -> None:
    settle_vehicle(api, flying=False)


@pytest.fixture
def flying(api: httpx.Client) -> None:
    settle_vehicle(api, flying=True)


def _sliders(page: Any) -> dict[str, dict[str, Any]]:
    return {slider["id"]: slider for slider in page.evaluate(SLIDERS)}


def _per_px(slider: dict[str, Any]) -> float:
    """The slider's units per pixel of its thumb's travel."""
    return float((slider["max"] - slider["min"]) / (slider["width"] - THUMB_PX))


def _slider(page: Any, key: str) -> dict[str, Any]:
    return _sliders(page)[f"sp-{key}-slider"]


def test_every_slider_is_wide_and_a_position_pixel_is_a_fraction_of_a_metre(
    on_ground: None, small_page: Any
) -> None:
    take_control(small_page)
    figures = {}
    metres_per_px = {}
    for panel_type in PANEL_TYPES:
        small_page.select_option("#sp-type", panel_type)
        sliders = _sliders(small_page)
        assert len(sliders) >= 3, f"{panel_type}: {sliders}"
        for name, slider in sliders.items():
            figures[f"{panel_type} {name}"] = (round(slider["width"]), round(_per_px(slider), 3))
            assert slider["width"] >= MIN_SLIDER_PX, f"{panel_type} {name}: {slider}"
            # the slider takes the row's free width (its label, number and unit are above it)
            assert slider["width"] >= 0.9 * slider["rowWidth"], f"{panel_type} {name}: {slider}"
            if slider["unit"] == "m":
                metres_per_px[f"{panel_type} {name}"] = _per_px(slider)
    assert sorted(metres_per_px) == [
        "position sp-alt_m-slider",
        "position sp-east_m-slider",
        "position sp-north_m-slider",
    ]
    assert all(m <= MAX_POSITION_M_PER_PX for m in metres_per_px.values()), metres_per_px
    print(f"\nslider width px, units per px at 1280x800: {figures}")


def test_the_window_follows_the_setpoint_flown_and_a_value_near_an_end(
    on_ground: None, small_page: Any, api: httpx.Client, serve: Serve
) -> None:
    # observing: the fields and the windows follow the setpoint another pilot streams
    pilot = api.post("/vehicles/1/control", json={"takeover": True, "force": True})
    pilot.raise_for_status()
    lease = {"X-Lease-Id": pilot.json()["lease_id"]}
    try:
        streamed = api.put(
            "/vehicles/1/setpoint",
            json={"type": "position_ned", "north_m": 140.0, "east_m": -60.0, "down_m": -5.0},
            headers=lease,
        )
        assert streamed.status_code == 200, streamed.text
        # the fields follow the state as it is drawn, not necessarily in one frame
        small_page.wait_for_function(
            "document.getElementById('sp-north_m').value === '140'"
            " && document.getElementById('sp-east_m').value === '-60'",
            timeout=15_000,
        )
        north = _slider(small_page, "north_m")
        assert (north["min"], north["max"], north["value"]) == (115, 165, 140)
        east = _slider(small_page, "east_m")
        assert (east["min"], east["max"], east["value"]) == (-85, -35, -60)
    finally:
        api.delete("/vehicles/1/control", headers=lease)
    settle_vehicle(api, flying=False)

    take_control(small_page)
    small_page.click("#sp-from-here")
    assert _slider(small_page, "north_m")["min"] == pytest.approx(-25, abs=1)
    # the number box takes what the API takes, far outside the slider's window: the window
    # moves to it
    schema = httpx.get(f"{serve.base}/openapi.json").json()["components"]["schemas"]
    north_limit = next(
        branch["maximum"]
        for name, body in schema.items()
        if "position" in name.lower() and "north_m" in body.get("properties", {})
        for branch in body["properties"]["north_m"].get("anyOf", [body["properties"]["north_m"]])
        if "maximum" in branch
    )
    assert float(small_page.get_attribute("#sp-north_m", "max") or "nan") == north_limit
    small_page.fill("#sp-north_m", "-1234.5")
    north = _slider(small_page, "north_m")
    assert north["value"] == -1234.5
    assert north["min"] == pytest.approx(-1234.5 - 25, abs=0.5)
    assert north["max"] == pytest.approx(-1234.5 + 25, abs=0.5)
    small_page.click("#sp-from-here")  # back to where the vehicle is
    # a drag that ends near an end of the window re-centres it on the value, which stays
    value = drag_slider_to(small_page, "#sp-east_m-slider", 24.0)
    assert value > 20.0
    east = _slider(small_page, "east_m")
    assert east["value"] == value
    assert east["min"] == pytest.approx(value - 25, abs=0.6)
    assert east["max"] == pytest.approx(value + 25, abs=0.6)
    # the altitude's window never goes below the ground
    assert _slider(small_page, "alt_m")["min"] == 0


def test_dragging_north_a_few_pixels_moves_the_setpoint_less_than_a_metre(
    flying: None, small_page: Any, api: httpx.Client
) -> None:
    take_control(small_page)
    start_offboard_here(small_page, api)
    before = vehicle_state(api)["setpoint"]
    assert before["type"] == "position_ned"
    north = _slider(small_page, "north_m")
    # the window is centred on where the vehicle is
    assert (north["min"] + north["max"]) / 2 == pytest.approx(before["north_m"], abs=0.6)
    box = small_page.locator("#sp-north_m-slider").bounding_box()
    x = (
        box["x"]
        + THUMB_PX / 2
        + (north["value"] - north["min"])
        / (north["max"] - north["min"])
        * (box["width"] - THUMB_PX)
    )
    y = box["y"] + box["height"] / 2
    small_page.mouse.move(x, y)
    small_page.mouse.down()
    for dx in (1, 2, 3):  # a hand's small drag, pixel by pixel
        small_page.mouse.move(x + dx, y)
    small_page.mouse.up()
    shown = float(small_page.input_value("#sp-north_m"))
    assert shown != north["value"]

    def sent() -> dict[str, Any] | None:
        setpoint: dict[str, Any] | None = vehicle_state(api)["setpoint"]
        return setpoint if setpoint and abs(setpoint["north_m"] - shown) < 1e-6 else None

    after = float(wait_for(f"the setpoint at the slider's north {shown} m", sent, 15.0)["north_m"])
    moved = abs(after - before["north_m"])
    assert 0.0 < moved < 1.0, (before, after)
    print(f"\n3 px drag of the north slider moved the setpoint {moved:.2f} m")
    wait_for(
        "the vehicle within 0.3 m of the new setpoint",
        lambda: abs(vehicle_state(api)["position_ned"]["north_m"] - after) < 0.3,
        30.0,
    )
