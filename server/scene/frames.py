"""Conversions from PX4's NED world / FRD body frames to viser's z-up ENU world / FLU body.

PX4 reports position in local NED (x north, y east, z down) and attitude as the rotation of
the FRD body (forward, right, down) in NED. viser draws in a right-handed z-up world, which
the scene treats as ENU (x east, y north, z up); vehicle models are built in FLU (forward,
left, up), so a model drawn with the identity pose faces east, its nose along +x.
Rotations are viser.transforms' and geodesy is pymap3d's (WGS-84).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pymap3d
import viser.transforms as vtf

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

# Both are half turns, so each is its own inverse: NED↔ENU swaps x/y and negates z (about the
# north-east diagonal); FRD↔FLU negates y and z (about the nose).
_ENU_FROM_NED = vtf.SO3.from_matrix(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]))
_FRD_FROM_FLU = vtf.SO3.from_x_radians(np.pi)


def ned_to_enu(north_m: float, east_m: float, down_m: float) -> Vec3:
    return (east_m, north_m, -down_m)


def enu_to_ned(east_m: float, north_m: float, up_m: float) -> Vec3:
    return (north_m, east_m, -up_m)


def attitude_enu_flu(roll_deg: float, pitch_deg: float, yaw_deg: float) -> vtf.SO3:
    """Body FLU → ENU rotation for a vehicle whose NED attitude is (roll, pitch, yaw).

    PX4's aerospace ZYX Euler angles (yaw, then pitch, then roll) are viser's
    ``from_rpy_radians`` convention, applied to the FRD body in NED.
    """
    body_ned = vtf.SO3.from_rpy_radians(
        np.radians(roll_deg), np.radians(pitch_deg), np.radians(yaw_deg)
    )
    return _ENU_FROM_NED @ body_ned @ _FRD_FROM_FLU


def rotation_enu_flu(roll_deg: float, pitch_deg: float, yaw_deg: float) -> npt.NDArray[np.float64]:
    """The same rotation as :func:`attitude_enu_flu`, as a 3×3 matrix."""
    return attitude_enu_flu(roll_deg, pitch_deg, yaw_deg).as_matrix().astype(np.float64)


def quat_wxyz_from_matrix(m: npt.NDArray[np.float64]) -> Quat:
    """Unit quaternion (w, x, y, z) of a proper rotation matrix, w ≥ 0."""
    return _wxyz(vtf.SO3.from_matrix(m))


def attitude_wxyz_enu(roll_deg: float, pitch_deg: float, yaw_deg: float) -> Quat:
    """viser orientation (wxyz) of an FLU model for a vehicle with this NED attitude."""
    return _wxyz(attitude_enu_flu(roll_deg, pitch_deg, yaw_deg))


def _wxyz(rotation: vtf.SO3) -> Quat:
    # q and -q are the same rotation; one sign (w ≥ 0) keeps successive poses comparable.
    w, x, y, z = (float(c) for c in rotation.wxyz)
    sign = -1.0 if w < 0.0 else 1.0
    return (sign * w, sign * x, sign * y, sign * z)


def geodetic_offset_enu(
    lat_deg: float, lon_deg: float, alt_amsl_m: float,
    ref_lat_deg: float, ref_lon_deg: float, ref_alt_amsl_m: float,
) -> Vec3:
    """ENU position of a geodetic point relative to a reference (e.g. another vehicle's origin)."""
    e, n, u = pymap3d.geodetic2enu(
        lat_deg, lon_deg, alt_amsl_m, ref_lat_deg, ref_lon_deg, ref_alt_amsl_m
    )
    return (float(e), float(n), float(u))


def enu_to_geodetic(
    east_m: float, north_m: float, up_m: float,
    ref_lat_deg: float, ref_lon_deg: float, ref_alt_amsl_m: float,
) -> tuple[float, float, float]:
    """(lat_deg, lon_deg, alt_amsl_m) of an ENU point relative to a geodetic reference."""
    lat, lon, alt = pymap3d.enu2geodetic(
        east_m, north_m, up_m, ref_lat_deg, ref_lon_deg, ref_alt_amsl_m
    )
    return (float(lat), float(lon), float(alt))


def ray_hits_plane_z(origin: Vec3, direction: Vec3, plane_z: float) -> Vec3 | None:
    """Where a click ray meets the horizontal plane z = plane_z, or None if it never does."""
    dz = direction[2]
    if abs(dz) < 1e-9:
        return None
    t = (plane_z - origin[2]) / dz
    if t <= 0.0:
        return None
    return (origin[0] + t * direction[0], origin[1] + t * direction[1], plane_z)
