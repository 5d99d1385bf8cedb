"""Fleet vehicles in the scene: a fleet server's view hands the scene each fleet vehicle's
state JSON (FleetScene.show); the scene places it by its global position relative to the
local vehicles' origin, greys it out when its edge is lost, and removes it when forgotten."""

from __future__ import annotations

import threading
from collections.abc import AsyncIterator
from typing import Any

import pymap3d
import pytest

from server.scene.fleet_view import LOST_COLOUR, fleet_pose
from server.scene.hub import SceneHub
from server.scene.styling import STATE_COLOURS
from tests.api.state_fakes import pushing, scene_fed_by
from tests.waiting import wait_for

from .conftest import ORIGIN, FakeVehicle

# a fleet vehicle 100 m north, 20 m west of the local vehicle's origin, 10 m above it
NORTH_M, EAST_M, UP_M = 100.0, -20.0, 10.0


def fleet_state(**changes: Any) -> dict[str, Any]:
    lat, lon, alt = pymap3d.enu2geodetic(
        EAST_M, NORTH_M, UP_M, ORIGIN.lat_deg, ORIGIN.lon_deg, ORIGIN.alt_amsl_m
    )
    state: dict[str, Any] = {
        "id": 1, "type": "QUADROTOR", "connected": True, "mode": "OFFBOARD",
        "user_mode": "OFFBOARD", "armed": True, "system_status": "ACTIVE",
        "global": {"lat_deg": float(lat), "lon_deg": float(lon), "alt_amsl_m": float(alt),
                   "alt_rel_m": UP_M},
        "attitude": {"roll_deg": 0.0, "pitch_deg": 0.0, "yaw_deg": 90.0},
        "home": {"lat_deg": ORIGIN.lat_deg, "lon_deg": ORIGIN.lon_deg,
                 "alt_amsl_m": ORIGIN.alt_amsl_m},
    }
    state.update(changes)
    return state


def test_a_state_without_a_global_position_is_not_drawn() -> None:
    assert fleet_pose("a/1", fleet_state(**{"global": None}), alive=True) is None
    nan_lat = fleet_state()
    nan_lat["global"] = {**nan_lat["global"], "lat_deg": float("nan")}
    assert fleet_pose("a/1", nan_lat, alive=True) is None


def test_the_pose_takes_the_scene_colours_and_lost_is_grey() -> None:
    flying = fleet_pose("a/1", fleet_state(), alive=True)
    assert flying is not None
    assert flying.colour == STATE_COLOURS["offboard"]
    assert flying.label == "a/1 OFFBOARD"
    lost = fleet_pose("a/1", fleet_state(), alive=False)
    assert lost is not None
    assert lost.colour == LOST_COLOUR
    assert lost.label == "a/1 LOST"
    link_lost = fleet_pose("a/1", fleet_state(connected=False), alive=True)
    assert link_lost is not None
    assert link_lost.colour == LOST_COLOUR


@pytest.fixture
async def hub() -> AsyncIterator[SceneHub]:
    hub = SceneHub(max_rate_hz=20.0)
    async with scene_fed_by(hub, [pushing(FakeVehicle(1))]):
        await wait_for(lambda: hub.status()["vehicles"], 20.0, "the local vehicle in the scene")
        yield hub


async def test_fleet_vehicles_are_placed_by_their_global_position(hub: SceneHub) -> None:
    # the fleet view calls from its own (Zenoh) thread
    feeder = threading.Thread(
        target=lambda: [hub.fleet.show(f"edge-{e}/1", fleet_state()) for e in "ab"]
    )
    feeder.start()
    feeder.join()
    await wait_for(lambda: hub.status()["fleet_vehicles"] == ["edge-a/1", "edge-b/1"], 20.0,
                   "both fleet vehicles drawn")
    view = hub._fleet_views["edge-a/1"]
    assert view.position_enu is not None
    east, north, up = view.position_enu
    assert east == pytest.approx(EAST_M, abs=0.01)
    assert north == pytest.approx(NORTH_M, abs=0.01)
    assert up == pytest.approx(UP_M, abs=0.01)
    assert hub._follow is not None
    assert "fleet edge-b/1" in hub._follow.options

    hub.fleet.show("edge-a/1", fleet_state(), alive=False)
    await wait_for(lambda: view.label.text == "edge-a/1 LOST", 20.0,
                   "the lost vehicle relabelled")
    assert view.model._hull_colour == LOST_COLOUR

    hub.fleet.forget("edge-a/1")
    await wait_for(lambda: hub.status()["fleet_vehicles"] == ["edge-b/1"], 20.0,
                   "the forgotten vehicle removed")
    assert "fleet edge-a/1" not in hub._follow.options
