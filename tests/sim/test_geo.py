"""Geodesy around the local origin: the fast telemetry path agrees with pymap3d."""

from __future__ import annotations

import pytest

from sim.lib.geo import LocalOrigin


@pytest.mark.parametrize("ned", [(0.0, 0.0, 0.0), (40.0, -30.0, -20.0), (800.0, 650.0, -120.0),
                                 (-2500.0, 10.0, -60.0)])
def test_fast_conversion_matches_pymap3d_within_a_millimetre(
    ned: tuple[float, float, float],
) -> None:
    origin = LocalOrigin()
    exact = origin.to_geodetic_exact(*ned)
    origin.to_geodetic(ned[0] - 30.0, ned[1] + 20.0, ned[2])  # anchor nearby, then move
    fast = origin.to_geodetic(*ned)
    back = origin.to_ned(fast.lat_deg, fast.lon_deg, fast.alt_m)
    assert back == pytest.approx(list(ned), abs=1e-3)
    assert fast.alt_m == pytest.approx(exact.alt_m, abs=1e-3)


def test_round_trip_through_geodetic() -> None:
    origin = LocalOrigin(47.0, 8.0, 400.0)
    point = origin.to_geodetic_exact(12.0, -7.0, -3.0)
    assert origin.to_ned(point.lat_deg, point.lon_deg, point.alt_m) == pytest.approx(
        [12.0, -7.0, -3.0], abs=1e-6)
    assert origin.down_of_altitude(410.0) == -10.0
