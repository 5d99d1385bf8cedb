"""NED/FRD → ENU/FLU conversions used to place and orient vehicle models."""

from __future__ import annotations

import math

import numpy as np
import pytest

from server.scene.frames import (
    attitude_wxyz_enu,
    enu_to_geodetic,
    enu_to_ned,
    geodetic_offset_enu,
    ned_to_enu,
    quat_wxyz_from_matrix,
    ray_hits_plane_z,
    rotation_enu_flu,
)


def _rotate(wxyz: tuple[float, float, float, float], v: tuple[float, float, float]) -> np.ndarray:
    w, x, y, z = wxyz
    q = np.array([x, y, z])
    vec = np.array(v, dtype=float)
    return vec + 2.0 * np.cross(q, np.cross(q, vec) + w * vec)


def test_ned_position_maps_north_to_y_east_to_x_and_down_to_minus_z() -> None:
    assert ned_to_enu(1.0, 2.0, 3.0) == (2.0, 1.0, -3.0)
    assert enu_to_ned(*ned_to_enu(4.0, -5.0, -6.0)) == (4.0, -5.0, -6.0)


@pytest.mark.parametrize(
    ("yaw_deg", "nose_enu"),
    [(0.0, (0, 1, 0)), (90.0, (1, 0, 0)), (180.0, (0, -1, 0)), (-90.0, (-1, 0, 0))],
)
def test_yaw_turns_the_nose_clockwise_from_north(yaw_deg: float, nose_enu: tuple[int, ...]) -> None:
    q = attitude_wxyz_enu(0.0, 0.0, yaw_deg)
    np.testing.assert_allclose(_rotate(q, (1.0, 0.0, 0.0)), nose_enu, atol=1e-9)
    np.testing.assert_allclose(_rotate(q, (0.0, 0.0, 1.0)), (0, 0, 1), atol=1e-9)


def test_positive_pitch_raises_the_nose() -> None:
    nose = _rotate(attitude_wxyz_enu(0.0, 30.0, 0.0), (1.0, 0.0, 0.0))
    np.testing.assert_allclose(nose, (0.0, math.cos(math.radians(30)), math.sin(math.radians(30))),
                               atol=1e-9)


def test_positive_roll_drops_the_right_wing() -> None:
    right_flu = (0.0, -1.0, 0.0)
    right = _rotate(attitude_wxyz_enu(20.0, 0.0, 0.0), right_flu)
    assert right[2] < -0.3
    # heading north, the right wing points east
    assert right[0] > 0.9


def test_combined_attitude_quaternion_matches_its_matrix() -> None:
    rng = np.random.default_rng(7)
    for roll, pitch, yaw in rng.uniform(-170, 170, size=(50, 3)):
        m = rotation_enu_flu(roll, pitch * 0.5, yaw)
        q = attitude_wxyz_enu(roll, pitch * 0.5, yaw)
        assert math.isclose(sum(c * c for c in q), 1.0, rel_tol=1e-9)
        for axis in np.eye(3):
            np.testing.assert_allclose(_rotate(q, tuple(axis)), m @ axis, atol=1e-9)
        assert np.linalg.det(m) == pytest.approx(1.0)


def test_quaternion_of_half_turn_matrices_is_well_defined() -> None:
    for m in (np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])):
        q = quat_wxyz_from_matrix(m)
        for axis in np.eye(3):
            np.testing.assert_allclose(_rotate(q, tuple(axis)), m @ axis, atol=1e-9)


def test_geodetic_offset_round_trips_through_enu() -> None:
    ref = (47.397742, 8.545594, 488.0)
    lat, lon, alt = enu_to_geodetic(30.0, -40.0, 5.0, *ref)
    east, north, up = geodetic_offset_enu(lat, lon, alt, *ref)
    assert (east, north, up) == pytest.approx((30.0, -40.0, 5.0), abs=1e-6)
    assert lat < ref[0]
    assert lon > ref[1]


def test_click_ray_meets_ground_plane_only_in_front() -> None:
    hit = ray_hits_plane_z((0.0, 0.0, 10.0), (1.0, 0.0, -1.0), 0.0)
    assert hit == pytest.approx((10.0, 0.0, 0.0))
    assert ray_hits_plane_z((0.0, 0.0, 10.0), (1.0, 0.0, 1.0), 0.0) is None
    assert ray_hits_plane_z((0.0, 0.0, 10.0), (1.0, 0.0, 0.0), 0.0) is None
