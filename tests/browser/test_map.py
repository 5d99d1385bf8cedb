"""The 2D map in Chromium against `skyhelm serve` with the simulated quad: the vehicle with
its heading and home, the offline metre grid, a click on the map that flies the vehicle
there, and tiles when the server names a tile URL."""

from __future__ import annotations

import base64
import math
from typing import Any

import httpx
import pymap3d
import pytest

from .flows import click_and_wait_result, settle_vehicle, take_control
from .harness import altitude_m, vehicle_state, wait_for

SERVE_ARGS = ["--sim-speed", "3"]
# A 1x1 PNG, what the intercepted tile requests answer.
PNG_1PX = base64.b64decode(
    "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mNkYPhfDwAChwGA60e6kgAAAABJRU5ErkJggg=="
)


def _map_ready(page: Any) -> None:
    page.wait_for_selector(".map-vehicle", timeout=30_000)


def _offset_m(state: dict[str, Any], lat: float, lon: float) -> tuple[float, float]:
    """(north, east) of lat/lon from the vehicle, in metres (pymap3d, WGS-84)."""
    here = state["global"]
    north, east, _ = pymap3d.geodetic2ned(lat, lon, 0.0, here["lat_deg"], here["lon_deg"], 0.0)
    return float(north), float(east)


def _click_map_at(page: Any, lat: float, lon: float) -> None:
    point = page.evaluate("([lat, lon]) => window.skyhelm.map.pagePoint(lat, lon)", [lat, lon])
    page.mouse.click(point["x"], point["y"])
    page.wait_for_selector("#map-goto", timeout=10_000)


def test_map_shows_the_vehicle_with_its_heading_home_grid_scale_and_north(
    page: Any, api: httpx.Client
) -> None:
    settle_vehicle(api, flying=False)
    _map_ready(page)
    # the page was open while the vehicle landed: it draws the disarm when the state comes
    page.wait_for_selector('.map-vehicle[data-category="disarmed"]', timeout=10_000)
    heading = vehicle_state(api)["heading_deg"]
    shown = float(page.get_attribute(".map-vehicle", "data-heading-deg") or "nan")
    assert abs((shown - heading + 180.0) % 360.0 - 180.0) < 5.0
    # the arrow turns the short way across north (359° -> 1° is +2°, not a spin back)
    turned = page.evaluate(
        "() => { const l = window.skyhelm.map.layers.get(1); const kept = l.arrowDeg;"
        " l.arrowDeg = 359; const a = [l.turnTo(1), l.turnTo(350)]; l.arrowDeg = kept; return a; }"
    )
    assert turned == [361, 350]
    assert page.is_visible(".map-home")
    assert page.is_visible(".map-north")
    assert page.is_visible(".leaflet-control-scale-line")
    label = page.text_content(".map-grid-label") or ""
    assert label.startswith("grid ")
    assert page.locator("path.map-grid").count() >= 4
    # the vehicle sits where the API says it is
    state = vehicle_state(api)
    box = page.locator(".map-vehicle").bounding_box()
    point = page.evaluate(
        "([lat, lon]) => window.skyhelm.map.pagePoint(lat, lon)",
        [state["global"]["lat_deg"], state["global"]["lon_deg"]],
    )
    assert abs(box["x"] + box["width"] / 2 - point["x"]) < 4
    assert abs(box["y"] + box["height"] / 2 - point["y"]) < 4


def test_click_on_the_map_flies_the_vehicle_there(page: Any, api: httpx.Client) -> None:
    settle_vehicle(api, flying=True)
    take_control(page)
    _map_ready(page)
    start = vehicle_state(api)
    lat, lon, _ = pymap3d.ned2geodetic(
        12.0, -8.0, 0.0, start["global"]["lat_deg"], start["global"]["lon_deg"], 0.0
    )
    _click_map_at(page, float(lat), float(lon))
    page.fill("#map-goto-alt", "7")
    click_and_wait_result(page, "#map-goto-go")
    page.wait_for_selector("#map-goto", state="detached", timeout=10_000)
    # the map shows where the vehicle is sent (PX4's target, in Hold)
    page.wait_for_selector(".map-aim", timeout=15_000)

    def arrived() -> bool:
        state = vehicle_state(api)
        north, east = _offset_m(state, float(lat), float(lon))
        return math.hypot(north, east) < 1.5 and abs(altitude_m(state) - 7.0) < 1.0

    wait_for("the vehicle at the clicked point, 7 m up", arrived, 60.0)
    # the trail follows the flight
    assert page.locator("path.map-trail").count() >= 1


def test_map_asks_for_control_before_flying(page: Any, api: httpx.Client) -> None:
    settle_vehicle(api, flying=False)
    _map_ready(page)
    state = vehicle_state(api)
    lat, lon, _ = pymap3d.ned2geodetic(
        20.0, 15.0, 0.0, state["global"]["lat_deg"], state["global"]["lon_deg"], 0.0
    )
    _click_map_at(page, float(lat), float(lon))
    assert page.is_disabled("#map-goto-go")
    assert "take control" in (page.text_content("#map-goto-note") or "")
    page.keyboard.press("Escape")
    page.wait_for_selector("#map-goto", state="detached", timeout=5_000)


@pytest.fixture
def tiled_page(browser: Any, serve: Any) -> Any:
    """The page told (by an intercepted GET /config) to use tiles from a host that only
    this browser answers for: the page's side of map_tile_url."""
    tab = browser.new_page()
    tiles: list[str] = []
    tab.route(
        "**/api/v1/config",
        lambda route: route.fulfill(
            json={
                "map_tile_url": "https://tiles.skyhelm.invalid/{z}/{x}/{y}.png",
                "map_tile_attribution": "Test tiles",
            }
        ),
    )

    def tile(route: Any) -> None:
        tiles.append(route.request.url)
        route.fulfill(body=PNG_1PX, content_type="image/png")

    tab.route("https://tiles.skyhelm.invalid/**", tile)
    tab.goto(f"{serve.url}&scene=off")
    try:
        yield tab, tiles
    finally:
        tab.close()


def test_map_draws_tiles_from_the_configured_url_instead_of_the_grid(tiled_page: Any) -> None:
    tab, tiles = tiled_page
    _map_ready(tab)
    wait_for("tiles asked for", lambda: len(tiles) > 0, 20.0)
    assert all(url.endswith(".png") and url.count("/") >= 5 for url in tiles)
    tab.wait_for_selector("img.leaflet-tile", timeout=10_000)
    assert tab.locator("path.map-grid").count() == 0
    assert "Test tiles" in (tab.text_content(".leaflet-control-attribution") or "")
