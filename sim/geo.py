"""Local NED <-> geodetic conversions around the estimator's origin (pymap3d, WGS84)."""

from __future__ import annotations

from dataclasses import dataclass

import pymap3d

# SIH's default origin (SIH_LOC_LAT0, SIH_LOC_LON0, SIH_LOC_H0): Zurich, 489.4 m AMSL.
SIH_LOC_LAT0_DEG = 47.397742
SIH_LOC_LON0_DEG = 8.545594
SIH_LOC_H0_M = 489.4


@dataclass
class GeoPoint:
    lat_deg: float
    lon_deg: float
    alt_m: float


class LocalOrigin:
    """The local position's reference point (PX4's `vehicle_local_position.ref_*`)."""

    def __init__(
        self,
        lat_deg: float = SIH_LOC_LAT0_DEG,
        lon_deg: float = SIH_LOC_LON0_DEG,
        alt_m: float = SIH_LOC_H0_M,
    ) -> None:
        self.lat_deg = lat_deg
        self.lon_deg = lon_deg
        self.alt_m = alt_m

    def to_geodetic(self, north_m: float, east_m: float, down_m: float) -> GeoPoint:
        lat, lon, alt = pymap3d.ned2geodetic(
            north_m, east_m, down_m, self.lat_deg, self.lon_deg, self.alt_m
        )
        return GeoPoint(float(lat), float(lon), float(alt))

    def to_ned(self, lat_deg: float, lon_deg: float, alt_m: float) -> list[float]:
        north, east, down = pymap3d.geodetic2ned(
            lat_deg, lon_deg, alt_m, self.lat_deg, self.lon_deg, self.alt_m
        )
        return [float(north), float(east), float(down)]

    def down_of_altitude(self, alt_m: float) -> float:
        """NED down of an AMSL altitude (flat-earth vertical, as PX4's local frame is)."""
        return self.alt_m - alt_m
