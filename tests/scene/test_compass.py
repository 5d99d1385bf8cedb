"""The scene's north marker and compass rose: north is +y in the ENU scene, and the rose
follows the ground grid to home."""

from __future__ import annotations

import math

import numpy as np
import pytest
import viser

from server.link.core.state import HomeState
from server.scene.compass import (
    CARDINALS,
    RING_RADIUS_M,
    CompassRose,
    bearing_enu,
    north_arrow_segments,
    rose_segments,
)
from server.scene.hub import SceneHub
from tests.api.state_fakes import pushing, scene_fed_by
from tests.waiting import wait_for

from .conftest import ORIGIN, FakeVehicle


@pytest.mark.parametrize(
    ("bearing_deg", "east_m", "north_m"),
    [
        (0.0, 0.0, 5.0),
        (90.0, 5.0, 0.0),
        (180.0, 0.0, -5.0),
        (270.0, -5.0, 0.0),
        (45.0, 3.5355, 3.5355),
    ],
)
def test_bearings_point_the_compass_way_in_enu(
    bearing_deg: float, east_m: float, north_m: float
) -> None:
    east, north, _ = bearing_enu(bearing_deg, 5.0)
    assert east == pytest.approx(east_m, abs=1e-3)
    assert north == pytest.approx(north_m, abs=1e-3)


def test_north_arrow_points_to_plus_y_from_the_centre() -> None:
    shaft = north_arrow_segments()[0]
    np.testing.assert_allclose(shaft[0][:2], (0.0, 0.0), atol=1e-6)
    assert shaft[1][0] == pytest.approx(0.0, abs=1e-6)
    assert shaft[1][1] > RING_RADIUS_M
    # the head's strokes go back south from the tip, one each side
    heads = north_arrow_segments()[1:]
    assert {math.copysign(1.0, float(seg[1][0])) for seg in heads} == {-1.0, 1.0}
    assert all(seg[1][1] < shaft[1][1] for seg in heads)


def test_ring_lies_on_its_radius_above_the_ground() -> None:
    segments = rose_segments()
    ends = segments.reshape(-1, 3)
    radii = np.hypot(ends[:, 0], ends[:, 1])
    assert radii.max() == pytest.approx(RING_RADIUS_M, rel=1e-5)
    assert (ends[:, 2] > 0.0).all()
    # 12 ticks, every 30°, each reaching inward from the ring
    ticks = segments[-12:]
    inner = np.hypot(ticks[:, 0, 0], ticks[:, 0, 1])
    assert (inner < RING_RADIUS_M - 0.5).all()


def test_rose_labels_the_cardinal_points_and_moves_to_home(scene: viser.SceneApi) -> None:
    rose = CompassRose(scene, "/test_compass")
    assert set(rose.labels) == set(CARDINALS) == {"N", "E", "S", "W"}
    north = rose.labels["N"].position
    east = rose.labels["E"].position
    assert north[1] > RING_RADIUS_M
    assert abs(north[0]) < 1e-6
    assert east[0] > RING_RADIUS_M
    assert abs(east[1]) < 1e-6
    rose.place((3.0, -4.0, 0.5))
    np.testing.assert_allclose(rose.root.position, (3.0, -4.0, 0.5))


async def test_hub_puts_the_rose_on_home_with_the_ground_grid() -> None:
    fake = FakeVehicle(1)
    fake.overrides["home"] = HomeState(
        ORIGIN.lat_deg, ORIGIN.lon_deg, ORIGIN.alt_amsl_m, 4.0, -3.0, 0.5
    )
    hub = SceneHub(max_rate_hz=20.0)
    async with scene_fed_by(hub, [pushing(fake)]):
        compass = hub._compass
        assert compass is not None

        def on_home() -> bool:
            return bool(np.allclose(compass.root.position, (-3.0, 4.0, -0.5), atol=1e-3))

        await wait_for(on_home, 5.0, "the compass rose on home (ENU)")
        grid = hub._grid
        assert grid is not None
        np.testing.assert_allclose(grid.position, compass.root.position)
