"""Conversions from PX4's NED world / FRD body frames to viser's z-up ENU world / FLU body.

PX4 reports position in local NED (x north, y east, z down) and attitude as the rotation of
the FRD body (forward, right, down) in NED. viser draws in a right-handed z-up world, which
the scene treats as ENU (x east, y north, z up); vehicle models are built in FLU (forward,
left, up), so a model drawn with the identity pose faces east, its nose along +x.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pymap3d

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

# Both are their own inverse: NED↔ENU swaps x/y and negates z; FRD↔FLU negates y and z.
_NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_FLU_TO_FRD = np.diag([1.0, -1.0, -1.0])


def ned_to_enu(north_m: float, east_m: float, down_m: float) -> Vec3:
    return (east_m, north_m, -down_m)


def enu_to_ned(east_m: float, north_m: float, up_m: float) -> Vec3:
    return (north_m, east_m, -up_m)


def rotation_ned_frd(roll_deg: float, pitch_deg: float, yaw_deg: float) -> npt.NDArray[np.float64]:
    """Body FRD → NED rotation matrix from aerospace ZYX Euler angles (PX4's convention)."""
    r, p, y = (math.radians(a) for a in (roll_deg, pitch_deg, yaw_deg))
    cr, sr = math.cos(r), math.sin(r)
    cp, sp = math.cos(p), math.sin(p)
    cy, sy = math.cos(y), math.sin(y)
    return np.array(
        [
            [cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
            [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
            [-sp, sr * cp, cr * cp],
        ]
    )


def rotation_enu_flu(roll_deg: float, pitch_deg: float, yaw_deg: float) -> npt.NDArray[np.float64]:
    """Body FLU → ENU rotation for a vehicle whose NED attitude is (roll, pitch, yaw)."""
    body_ned = rotation_ned_frd(roll_deg, pitch_deg, yaw_deg)
    result: npt.NDArray[np.float64] = _NED_TO_ENU @ body_ned @ _FLU_TO_FRD
    return result


def quat_wxyz_from_matrix(m: npt.NDArray[np.float64]) -> Quat:
    """Unit quaternion (w, x, y, z) of a proper rotation matrix, w ≥ 0."""
    trace = float(m[0, 0] + m[1, 1] + m[2, 2])
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = (0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = ((m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s)
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = ((m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = ((m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s)
    w, x, y, z = (float(c) for c in q)
    sign = -1.0 if w < 0.0 else 1.0
    return (sign * w, sign * x, sign * y, sign * z)


def attitude_wxyz_enu(roll_deg: float, pitch_deg: float, yaw_deg: float) -> Quat:
    """viser orientation (wxyz) of an FLU model for a vehicle with this NED attitude."""
    return quat_wxyz_from_matrix(rotation_enu_flu(roll_deg, pitch_deg, yaw_deg))


def yaw_wxyz_enu(yaw_deg: float) -> Quat:
    """Orientation of a level model heading `yaw_deg` (0 = north, clockwise seen from above)."""
    return attitude_wxyz_enu(0.0, 0.0, yaw_deg)


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
