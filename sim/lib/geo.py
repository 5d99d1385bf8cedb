"""Local NED <-> geodetic conversions around the estimator's origin (pymap3d, WGS84)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pymap3d

# SIH's default origin (SIH_LOC_LAT0, SIH_LOC_LON0, SIH_LOC_H0): Zurich, 489.4 m AMSL.
SIH_LOC_LAT0_DEG = 47.397742
SIH_LOC_LON0_DEG = 8.545594
SIH_LOC_H0_M = 489.4


# The largest altitude a MAVLink int32 millimetre field (HOME_POSITION.altitude) carries.
MAVLINK_ALT_LIMIT_M = 2_147_483.0


@dataclass
class GeoPoint:
    lat_deg: float
    lon_deg: float
    alt_m: float


def wrap_lon_deg(lon_deg: float) -> float:
    """Longitude in [-180, 180): the antimeridian crossed, not overflowed."""
    if -180.0 <= lon_deg < 180.0:
        return lon_deg
    return (lon_deg + 180.0) % 360.0 - 180.0


def geo_point(lat_deg: float, lon_deg: float, alt_m: float) -> GeoPoint:
    """A point on the globe: latitude within the poles, longitude wrapped."""
    return GeoPoint(max(-90.0, min(90.0, lat_deg)), wrap_lon_deg(lon_deg), alt_m)


def is_valid_lat_lon(lat_deg: float, lon_deg: float) -> bool:
    """The range EKF2's checkLatLonValidity accepts for an origin."""
    return (
        math.isfinite(lat_deg) and abs(lat_deg) <= 90.0
        and math.isfinite(lon_deg) and abs(lon_deg) <= 180.0
    )


# pymap3d's exact conversion costs a few hundred microseconds, too much for 50 Hz telemetry
# of many vehicles. Within this distance of a point pymap3d converted exactly, positions
# are mapped with pymap3d's own local derivatives there (error below a millimetre).
LINEAR_RANGE_M = 50.0
_DERIVATIVE_STEP_M = 1.0
# Towards a pole longitude turns fast over a few metres and the linear map no longer holds:
# beyond this latitude every conversion is exact.
LINEAR_MAX_LAT_DEG = 89.0


class _Anchor:
    """An exactly converted point and the local d(lat, lon, alt)/d(north, east, down)."""

    def __init__(self, origin: LocalOrigin, ned_m: tuple[float, float, float]) -> None:
        self.ned_m = ned_m
        self.point = origin.to_geodetic_exact(*ned_m)
        north, east, down = ned_m
        step = _DERIVATIVE_STEP_M
        to_north = origin.to_geodetic_exact(north + step, east, down)
        to_east = origin.to_geodetic_exact(north, east + step, down)
        self.dlat_dnorth = (to_north.lat_deg - self.point.lat_deg) / step
        self.dlon_dnorth = (to_north.lon_deg - self.point.lon_deg) / step
        self.dlat_deast = (to_east.lat_deg - self.point.lat_deg) / step
        self.dlon_deast = (to_east.lon_deg - self.point.lon_deg) / step
        # Far from the origin, level NED motion changes the altitude (earth curvature).
        self.dalt_dnorth = (to_north.alt_m - self.point.alt_m) / step
        self.dalt_deast = (to_east.alt_m - self.point.alt_m) / step

    def covers(self, north_m: float, east_m: float, down_m: float) -> bool:
        n0, e0, d0 = self.ned_m
        return max(abs(north_m - n0), abs(east_m - e0), abs(down_m - d0)) <= LINEAR_RANGE_M

    def to_geodetic(self, north_m: float, east_m: float, down_m: float) -> GeoPoint:
        dn = north_m - self.ned_m[0]
        de = east_m - self.ned_m[1]
        return geo_point(
            self.point.lat_deg + self.dlat_dnorth * dn + self.dlat_deast * de,
            self.point.lon_deg + self.dlon_dnorth * dn + self.dlon_deast * de,
            self.point.alt_m - (down_m - self.ned_m[2])
            + self.dalt_dnorth * dn + self.dalt_deast * de,
        )


@dataclass(eq=False)
class LocalOrigin:
    """The local position's reference point (PX4's `vehicle_local_position.ref_*`)."""

    lat_deg: float = SIH_LOC_LAT0_DEG
    lon_deg: float = SIH_LOC_LON0_DEG
    alt_m: float = SIH_LOC_H0_M
    _anchor: _Anchor | None = field(default=None, init=False, repr=False)

    def to_geodetic(self, north_m: float, east_m: float, down_m: float) -> GeoPoint:
        """Fast conversion for telemetry (see LINEAR_RANGE_M)."""
        anchor = self._anchor
        if anchor is None or not anchor.covers(north_m, east_m, down_m):
            anchor = self._anchor = _Anchor(self, (north_m, east_m, down_m))
        if abs(anchor.point.lat_deg) > LINEAR_MAX_LAT_DEG:
            return self.to_geodetic_exact(north_m, east_m, down_m)
        point = anchor.to_geodetic(north_m, east_m, down_m)
        return point if _is_finite_point(point) else self.to_geodetic_exact(north_m, east_m, down_m)

    def to_geodetic_exact(self, north_m: float, east_m: float, down_m: float) -> GeoPoint:
        lat, lon, alt = pymap3d.ned2geodetic(
            north_m, east_m, down_m, self.lat_deg, self.lon_deg, self.alt_m
        )
        point = geo_point(float(lat), float(lon), float(alt))
        if _is_finite_point(point):
            return point
        # no finite answer (a position overflowed far beyond the globe): report the origin
        return geo_point(self.lat_deg, self.lon_deg, self.alt_m)

    def to_ned(self, lat_deg: float, lon_deg: float, alt_m: float) -> list[float]:
        north, east, down = pymap3d.geodetic2ned(
            lat_deg, lon_deg, alt_m, self.lat_deg, self.lon_deg, self.alt_m
        )
        return [float(north), float(east), float(down)]

    def down_of_altitude(self, alt_m: float) -> float:
        """NED down of an AMSL altitude (flat-earth vertical, as PX4's local frame is)."""
        return self.alt_m - alt_m


def _is_finite_point(point: GeoPoint) -> bool:
    total = point.lat_deg + point.lon_deg + point.alt_m
    return total - total == 0.0
