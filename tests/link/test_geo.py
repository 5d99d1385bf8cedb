"""Geodesy helpers agree with WGS-84 figures."""

import pytest

from server.link.codec.geo import ground_distance_m, ned_from_geodetic_m

ORIGIN = (47.397742, 8.545594, 488.0)


def test_one_arc_minute_of_latitude_near_zurich_is_about_1853_m() -> None:
    north_m, east_m, down_m = ned_from_geodetic_m(47.397742 + 1 / 60, 8.545594, 488.0, *ORIGIN)
    # WGS-84 meridian arc at 47.4°: 1853.3 m per minute; the point lies slightly below the
    # tangent plane, so it is "down" by a few tenths of a metre.
    assert north_m == pytest.approx(1853.3, abs=1.0)
    assert abs(east_m) < 1e-6
    assert 0.1 < down_m < 0.5


def test_east_offset_shrinks_with_the_cosine_of_latitude() -> None:
    _, east_m, _ = ned_from_geodetic_m(47.397742, 8.545594 + 0.001, 488.0, *ORIGIN)
    assert east_m == pytest.approx(75.5, abs=0.2)


def test_ground_distance_is_symmetric_and_zero_at_the_same_point() -> None:
    a = (47.397742, 8.545594)
    b = (47.398742, 8.546594)
    assert ground_distance_m(*a, *a) == 0.0
    assert ground_distance_m(*a, *b) == pytest.approx(ground_distance_m(*b, *a), rel=1e-6)
    assert ground_distance_m(*a, *b) == pytest.approx(135.0, abs=2.0)
