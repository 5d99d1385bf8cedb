"""Geodesy for the link layer, by pymap3d (WGS-84): never hand-rolled."""

from __future__ import annotations

import math

import pymap3d


def ned_from_geodetic_m(
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    ref_lat_deg: float,
    ref_lon_deg: float,
    ref_alt_m: float,
) -> tuple[float, float, float]:
    """(north, east, down) in metres of a point seen from a reference point."""
    north_m, east_m, down_m = pymap3d.geodetic2ned(
        lat_deg, lon_deg, alt_m, ref_lat_deg, ref_lon_deg, ref_alt_m
    )
    return float(north_m), float(east_m), float(down_m)


def ground_distance_m(lat1_deg: float, lon1_deg: float, lat2_deg: float, lon2_deg: float) -> float:
    """Horizontal distance in metres between two points at the same height."""
    north_m, east_m, _ = ned_from_geodetic_m(lat2_deg, lon2_deg, 0.0, lat1_deg, lon1_deg, 0.0)
    return math.hypot(north_m, east_m)


def geodetic_from_ned_m(
    ned_m: tuple[float, float, float], ref_lat_deg: float, ref_lon_deg: float, ref_alt_m: float
) -> tuple[float, float, float]:
    """(lat, lon, alt) of the point ``ned_m`` (north, east, down) metres from a reference."""
    lat_deg, lon_deg, alt_m = pymap3d.ned2geodetic(*ned_m, ref_lat_deg, ref_lon_deg, ref_alt_m)
    return float(lat_deg), float(lon_deg), float(alt_m)
