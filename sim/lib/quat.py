"""Small rotation helpers on plain floats.

Quaternions are (w, x, y, z) and rotate body (FRD) to NED, as in `sim.lib.topics`. The physics
runs at 250 Hz for many vehicles in one process, and for 3-vectors plain float arithmetic is
several times faster than numpy, so everything here works on tuples and lists of floats.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def quat_multiply(a: Sequence[float], b: Sequence[float]) -> Quat:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_conjugate(q: Sequence[float]) -> Quat:
    return (q[0], -q[1], -q[2], -q[3])


def quat_normalized(q: Sequence[float]) -> Quat:
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not n > 1e-9 or not math.isfinite(n):
        return (1.0, 0.0, 0.0, 0.0)
    return (w / n, x / n, y / n, z / n)


def rotate_body_to_ned(q: Sequence[float], v: Sequence[float]) -> Vec3:
    """v expressed in NED, given v in body axes."""
    w, x, y, z = q
    vx, vy, vz = v
    # q v q* expanded; cheaper than two quaternion products
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (
        vx + w * tx + (y * tz - z * ty),
        vy + w * ty + (z * tx - x * tz),
        vz + w * tz + (x * ty - y * tx),
    )


def rotate_ned_to_body(q: Sequence[float], v: Sequence[float]) -> Vec3:
    return rotate_body_to_ned((q[0], -q[1], -q[2], -q[3]), v)


def body_z_axis_ned(q: Sequence[float]) -> Vec3:
    """Third column of the rotation matrix: where body down points in NED."""
    w, x, y, z = q
    return (2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y))


def body_x_axis_ned(q: Sequence[float]) -> Vec3:
    w, x, y, z = q
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y))


def quat_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Quat:
    cr, sr = math.cos(roll_rad / 2.0), math.sin(roll_rad / 2.0)
    cp, sp = math.cos(pitch_rad / 2.0), math.sin(pitch_rad / 2.0)
    cy, sy = math.cos(yaw_rad / 2.0), math.sin(yaw_rad / 2.0)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def euler_from_quat(q: Sequence[float]) -> Vec3:
    """(roll, pitch, yaw) in radians, ZYX convention like PX4's Eulerf."""
    w, x, y, z = q
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    sinp = max(-1.0, min(1.0, 2.0 * (w * y - z * x)))
    pitch = math.asin(sinp)
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return (roll, pitch, yaw)


def yaw_from_quat(q: Sequence[float]) -> float:
    w, x, y, z = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quat_from_yaw(yaw_rad: float) -> Quat:
    return (math.cos(yaw_rad / 2.0), 0.0, 0.0, math.sin(yaw_rad / 2.0))


def quat_integrate(q: Sequence[float], rates_body_rad_s: Sequence[float], dt_s: float) -> Quat:
    """Advance q by body rates over dt_s (exact rotation for constant rates), normalised."""
    p, r_q, r = rates_body_rad_s
    angle = math.sqrt(p * p + r_q * r_q + r * r) * dt_s
    if angle < 1e-12:
        return quat_normalized(q)
    half = 0.5 * angle
    s = math.sin(half) / (angle / dt_s)
    dq = (math.cos(half), p * s, r_q * s, r * s)
    return quat_normalized(quat_multiply(q, dq))


def wrap_pi(angle_rad: float) -> float:
    if not math.isfinite(angle_rad):
        return 0.0
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def quat_from_body_z_and_yaw(body_z_ned: Sequence[float], yaw_rad: float) -> Quat:
    """Attitude whose body z axis is body_z_ned (unit) and whose heading is yaw_rad.

    Mirrors PX4's ControlMath::bodyzToAttitude: body x is the projection of the yaw
    direction onto the plane normal to body z.
    """
    zx, zy, zz = body_z_ned
    # y_C: unit vector perpendicular to the heading in the horizontal plane
    ycx, ycy = -math.sin(yaw_rad), math.cos(yaw_rad)
    # body_x = y_C × body_z
    bx = (ycy * zz, -ycx * zz, ycx * zy - ycy * zx)
    n = math.sqrt(bx[0] * bx[0] + bx[1] * bx[1] + bx[2] * bx[2])
    if n < 1e-6:
        return quat_from_yaw(yaw_rad)
    bx = (bx[0] / n, bx[1] / n, bx[2] / n)
    # body_y = body_z × body_x
    by = (zy * bx[2] - zz * bx[1], zz * bx[0] - zx * bx[2], zx * bx[1] - zy * bx[0])
    return quat_from_rotation_columns(bx, by, (zx, zy, zz))


def quat_from_rotation_columns(c0: Vec3, c1: Vec3, c2: Vec3) -> Quat:
    """Quaternion of the rotation matrix whose columns are c0, c1, c2."""
    m00, m10, m20 = c0
    m01, m11, m21 = c1
    m02, m12, m22 = c2
    tr = m00 + m11 + m22
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        q = (0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s)
    elif m00 > m11 and m00 > m22:
        s = math.sqrt(1.0 + m00 - m11 - m22) * 2.0
        q = ((m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s)
    elif m11 > m22:
        s = math.sqrt(1.0 + m11 - m00 - m22) * 2.0
        q = ((m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s)
    else:
        s = math.sqrt(1.0 + m22 - m00 - m11) * 2.0
        q = ((m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s)
    return quat_normalized(q)
