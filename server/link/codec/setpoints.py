"""Offboard setpoints to MAVLink: resolving offsets and the exact encoding of each kind.

The kinds themselves (fields, units, limits) are defined in ``setpoint_kinds``.
Type masks follow MAVSDK's offboard plugin, so a PX4 that flies MAVSDK flies these:
position+yaw 2552, velocity NED+yaw 2503, velocity body+yaw rate 1479, ...
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from pymavlink.dialects.v20 import development as mavlink
from pymavlink.quaternion import QuaternionBase

from skyhelm_wire.setpoint_kinds import (
    SETPOINT_KINDS,
    AccelerationNed,
    AltFrame,
    Attitude,
    BodyRates,
    OffsetBody,
    OffsetNed,
    PositionGlobal,
    PositionNed,
    PositionVelocityNed,
    RawLocal,
    Setpoint,
    VelocityBody,
    VelocityNed,
    describe,
)

MAV_FRAME_GLOBAL_INT = 5
MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_LOCAL_OFFSET_NED = 7
MAV_FRAME_BODY_NED = 8
MAV_FRAME_BODY_OFFSET_NED = 9
MAV_FRAME_GLOBAL_RELATIVE_ALT_INT = 6
MAV_FRAME_GLOBAL_TERRAIN_ALT_INT = 11

POSITION_TARGET_TYPEMASK_X_IGNORE = 1
POSITION_TARGET_TYPEMASK_Y_IGNORE = 2
POSITION_TARGET_TYPEMASK_Z_IGNORE = 4
POSITION_TARGET_TYPEMASK_VX_IGNORE = 8
POSITION_TARGET_TYPEMASK_VY_IGNORE = 16
POSITION_TARGET_TYPEMASK_VZ_IGNORE = 32
POSITION_TARGET_TYPEMASK_AX_IGNORE = 64
POSITION_TARGET_TYPEMASK_AY_IGNORE = 128
POSITION_TARGET_TYPEMASK_AZ_IGNORE = 256
POSITION_TARGET_TYPEMASK_FORCE_SET = 512
POSITION_TARGET_TYPEMASK_YAW_IGNORE = 1024
POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE = 2048

IGNORE_POSITION = (
    POSITION_TARGET_TYPEMASK_X_IGNORE
    | POSITION_TARGET_TYPEMASK_Y_IGNORE
    | POSITION_TARGET_TYPEMASK_Z_IGNORE
)
IGNORE_VELOCITY = (
    POSITION_TARGET_TYPEMASK_VX_IGNORE
    | POSITION_TARGET_TYPEMASK_VY_IGNORE
    | POSITION_TARGET_TYPEMASK_VZ_IGNORE
)
IGNORE_ACCELERATION = (
    POSITION_TARGET_TYPEMASK_AX_IGNORE
    | POSITION_TARGET_TYPEMASK_AY_IGNORE
    | POSITION_TARGET_TYPEMASK_AZ_IGNORE
)

ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE = 1
ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE = 2
ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE = 4
ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE = 64
ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE = 128
IGNORE_BODY_RATES = (
    ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
    | ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
)

__all__ = [
    "SETPOINT_KINDS",
    "AccelerationNed",
    "AltFrame",
    "Attitude",
    "BodyRates",
    "LocalFields",
    "OffsetBody",
    "OffsetNed",
    "PositionGlobal",
    "PositionNed",
    "PositionVelocityNed",
    "RawLocal",
    "SentSetpoint",
    "Setpoint",
    "VelocityBody",
    "VelocityNed",
    "describe",
    "encode",
    "local_fields",
    "resolve",
]

GLOBAL_FRAMES: dict[AltFrame, int] = {
    "amsl": MAV_FRAME_GLOBAL_INT,
    "relative": MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    "terrain": MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
}


@dataclass(frozen=True)
class SentSetpoint:
    """What went on the wire for a setpoint."""

    setpoint: Setpoint
    message: str
    frame: int
    type_mask: int


def resolve(
    sp: Setpoint, position_ned: tuple[float, float, float] | None, yaw_deg: float | None
) -> Setpoint:
    """Turn offsets into LOCAL_NED positions (PX4 rejects frames 7 and 9) and pin a missing
    yaw to the current heading, so the streamed setpoint does not drift with the vehicle.

    Raises LookupError when an offset needs a position or heading that is not known yet.
    """
    if isinstance(sp, OffsetNed | OffsetBody):
        if position_ned is None:
            raise LookupError("no local position yet")
        north, east, down = position_ned
        if isinstance(sp, OffsetBody):
            if yaw_deg is None:
                raise LookupError("no heading yet")
            yaw = math.radians(yaw_deg)
            d_north = sp.forward_m * math.cos(yaw) - sp.right_m * math.sin(yaw)
            d_east = sp.forward_m * math.sin(yaw) + sp.right_m * math.cos(yaw)
        else:
            d_north, d_east = sp.north_m, sp.east_m
        return PositionNed(
            north + d_north,
            east + d_east,
            down + sp.down_m,
            sp.yaw_deg if sp.yaw_deg is not None else yaw_deg,
        )
    if yaw_deg is None:
        return sp
    if isinstance(sp, PositionNed | PositionVelocityNed | PositionGlobal) and sp.yaw_deg is None:
        return replace(sp, yaw_deg=yaw_deg)
    if isinstance(sp, VelocityNed) and sp.yaw_deg is None and sp.yaw_rate_deg_s is None:
        return replace(sp, yaw_deg=yaw_deg)
    return sp


def _rad(value_deg: float | None) -> float:
    return 0.0 if value_deg is None else math.radians(value_deg)


def _yaw_bits(yaw_deg: float | None, yaw_rate_deg_s: float | None) -> int:
    bits = 0
    if yaw_deg is None:
        bits |= POSITION_TARGET_TYPEMASK_YAW_IGNORE
    if yaw_rate_deg_s is None:
        bits |= POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
    return bits


# A raw setpoint is exactly the wire fields, so one type serves both.
LocalFields = RawLocal

Axes = tuple[str, str, str]
_NED_M: Axes = ("north_m", "east_m", "down_m")
_NED_M_S: Axes = ("north_m_s", "east_m_s", "down_m_s")
_NED_M_S2: Axes = ("north_m_s2", "east_m_s2", "down_m_s2")


@dataclass(frozen=True)
class _LocalForm:
    """How a kind fills SET_POSITION_TARGET_LOCAL_NED: its frame and which of its fields are
    the x/y/z of position, velocity and acceleration (a group without fields, or with a None,
    is ignored in the type mask). ``yaw_deg`` and ``yaw_rate_deg_s`` are taken by name."""

    frame: int
    position: Axes | None = None
    velocity: Axes | None = None
    acceleration: Axes | None = None
    # a yaw rate of None still means "do not turn", which PX4 only honours as rate 0
    yaw_rate_none_is_zero: bool = False


_LOCAL_FORMS: dict[type[Setpoint], _LocalForm] = {
    PositionNed: _LocalForm(MAV_FRAME_LOCAL_NED, position=_NED_M),
    VelocityNed: _LocalForm(MAV_FRAME_LOCAL_NED, velocity=_NED_M_S),
    VelocityBody: _LocalForm(
        MAV_FRAME_BODY_NED,
        velocity=("forward_m_s", "right_m_s", "down_m_s"),
        yaw_rate_none_is_zero=True,
    ),
    AccelerationNed: _LocalForm(MAV_FRAME_LOCAL_NED, acceleration=_NED_M_S2),
    PositionVelocityNed: _LocalForm(MAV_FRAME_LOCAL_NED, _NED_M, _NED_M_S, _NED_M_S2),
}


def local_fields(sp: Setpoint) -> LocalFields | None:
    """The LOCAL_NED/BODY_NED form of a setpoint, or None if it is not a local one."""
    if isinstance(sp, RawLocal):
        return sp
    form = _LOCAL_FORMS.get(type(sp))
    if form is None:
        return None
    mask = 0
    vectors: list[tuple[float, float, float]] = []
    groups = (
        (form.position, IGNORE_POSITION),
        (form.velocity, IGNORE_VELOCITY),
        (form.acceleration, IGNORE_ACCELERATION),
    )
    for axes, ignore in groups:
        values = tuple(getattr(sp, name) for name in axes) if axes else (None,)
        if any(value is None for value in values):
            mask |= ignore
            values = (0.0, 0.0, 0.0)
        vectors.append(values)
    yaw_deg: float | None = getattr(sp, "yaw_deg", None)
    yaw_rate_deg_s: float | None = getattr(sp, "yaw_rate_deg_s", None)
    if form.yaw_rate_none_is_zero and yaw_rate_deg_s is None:
        yaw_rate_deg_s = 0.0
    mask |= _yaw_bits(yaw_deg, yaw_rate_deg_s)
    (x, y, z), (vx, vy, vz), (afx, afy, afz) = vectors
    return LocalFields(
        form.frame, mask, x, y, z, vx, vy, vz, afx, afy, afz, _rad(yaw_deg), _rad(yaw_rate_deg_s)
    )


def _quaternion(roll_deg: float, pitch_deg: float, yaw_deg: float) -> list[float]:
    """Hamilton quaternion (w, x, y, z) of ZYX Euler angles, as SET_ATTITUDE_TARGET wants:
    pymavlink's own conversion, the one its receivers use to read it back."""
    euler_rad = [math.radians(roll_deg), math.radians(pitch_deg), math.radians(yaw_deg)]
    return [float(c) for c in QuaternionBase(euler_rad).q]


def encode(
    sp: Setpoint,
    mav: mavlink.MAVLink,
    target_system: int,
    target_component: int,
    time_boot_ms: int = 0,
) -> tuple[mavlink.MAVLink_message, SentSetpoint]:
    """The MAVLink message for an already resolved setpoint (no offsets)."""
    fields = local_fields(sp)
    if fields is not None:
        msg = mav.set_position_target_local_ned_encode(
            time_boot_ms,
            target_system,
            target_component,
            fields.frame,
            fields.type_mask,
            fields.x,
            fields.y,
            fields.z,
            fields.vx,
            fields.vy,
            fields.vz,
            fields.afx,
            fields.afy,
            fields.afz,
            fields.yaw,
            fields.yaw_rate,
        )
        return msg, SentSetpoint(
            sp, "SET_POSITION_TARGET_LOCAL_NED", fields.frame, fields.type_mask
        )
    if isinstance(sp, PositionGlobal):
        frame = GLOBAL_FRAMES[sp.alt_frame]
        mask = IGNORE_VELOCITY | IGNORE_ACCELERATION | _yaw_bits(sp.yaw_deg, None)
        msg = mav.set_position_target_global_int_encode(
            time_boot_ms,
            target_system,
            target_component,
            frame,
            mask,
            round(sp.lat_deg * 1e7),
            round(sp.lon_deg * 1e7),
            sp.alt_m,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            _rad(sp.yaw_deg),
            0.0,
        )
        return msg, SentSetpoint(sp, "SET_POSITION_TARGET_GLOBAL_INT", frame, mask)
    if isinstance(sp, Attitude):
        mask = IGNORE_BODY_RATES
        q = _quaternion(sp.roll_deg, sp.pitch_deg, sp.yaw_deg)
        rates = (0.0, 0.0, 0.0)
    elif isinstance(sp, BodyRates):
        mask = ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
        q = [1.0, 0.0, 0.0, 0.0]
        rates = (
            math.radians(sp.roll_rate_deg_s),
            math.radians(sp.pitch_rate_deg_s),
            math.radians(sp.yaw_rate_deg_s),
        )
    else:
        raise TypeError(f"no MAVLink form for {sp!r} (offsets are resolved before encoding)")
    msg = mav.set_attitude_target_encode(
        time_boot_ms, target_system, target_component, mask, q, *rates, sp.thrust
    )
    return msg, SentSetpoint(sp, "SET_ATTITUDE_TARGET", 0, mask)
