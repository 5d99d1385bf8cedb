"""What PX4 accepts, per vehicle type, and the operator's safety envelope.

A setpoint PX4 would silently drop (mavlink_receiver only reports it as STATUSTEXT, if at
all) is refused here with the reason, before it reaches the link.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

# Envelope and SetpointRejected live with the envelope checks; re-exported for callers here
from server.link.codec.envelope import Envelope as Envelope
from server.link.codec.envelope import SetpointRejected as SetpointRejected
from server.link.codec.envelope import check_limit
from server.link.codec.geo import ground_distance_m
from server.link.codec.setpoints import (
    IGNORE_ACCELERATION,
    IGNORE_POSITION,
    IGNORE_VELOCITY,
    MAV_FRAME_BODY_NED,
    MAV_FRAME_LOCAL_NED,
    POSITION_TARGET_TYPEMASK_FORCE_SET,
    POSITION_TARGET_TYPEMASK_X_IGNORE,
    POSITION_TARGET_TYPEMASK_Y_IGNORE,
    POSITION_TARGET_TYPEMASK_Z_IGNORE,
    LocalFields,
    Setpoint,
    local_fields,
)
from skyhelm_wire.setpoint_kinds import Attitude, BodyRates, PositionGlobal, RawLocal, kind_fields

VehicleClass = Literal["multicopter", "fixed_wing", "vtol_transition", "rover"]
# What PX4 controls for a setpoint (its offboard control mode), which it accepts per vehicle type
Control = Literal["position", "velocity", "acceleration", "position_velocity", "attitude", "rates"]

_ALLOWED: dict[VehicleClass, frozenset[Control]] = {
    "multicopter": frozenset(
        {"position", "velocity", "acceleration", "position_velocity", "attitude", "rates"}
    ),
    "fixed_wing": frozenset({"position", "attitude", "rates"}),
    "vtol_transition": frozenset({"position"}),
    "rover": frozenset({"position", "velocity"}),
}
_CLASS_LABEL: dict[VehicleClass, str] = {
    "multicopter": "a multicopter",
    "fixed_wing": "a fixed wing (or VTOL in fixed-wing flight)",
    "vtol_transition": "a VTOL in transition",
    "rover": "a rover",
}

# MAV_TYPE values
_FIXED_WING = {1}
_VTOL = {19, 20, 21, 22, 23, 24, 25}
_ROVER = {10, 11}


@dataclass(frozen=True)
class Reference:
    """Where home is, for the envelope: local NED and, when known, global."""

    home_ned: tuple[float, float, float] = (0.0, 0.0, 0.0)
    home_lat_lon_alt: tuple[float, float, float] | None = None


def vehicle_class(mav_type: int, vtol_state: str) -> VehicleClass:
    if mav_type in _VTOL:
        if vtol_state == "FW":
            return "fixed_wing"
        if vtol_state.startswith("TRANSITION"):
            return "vtol_transition"
        return "multicopter"
    if mav_type in _FIXED_WING:
        return "fixed_wing"
    if mav_type in _ROVER:
        return "rover"
    return "multicopter"


def check(sp: Setpoint, vclass: VehicleClass, envelope: Envelope, ref: Reference) -> None:
    """Raise SetpointRejected if PX4 would drop ``sp`` or it leaves the envelope.

    ``sp`` must be resolved (offsets already turned into positions).
    """
    _check_quantities(sp)
    local = local_fields(sp)
    if isinstance(sp, RawLocal) and local is not None:
        _check_raw(local)
    control = _control(sp, local)
    if control not in _ALLOWED[vclass]:
        raise SetpointRejected(
            f"PX4 ignores {control.replace('_', '+')} setpoints on {_CLASS_LABEL[vclass]}",
            field="type",
        )
    _check_envelope(sp, local, envelope, ref)


def _check_quantities(sp: Setpoint) -> None:
    """Every number finite and within its kind's limits (which the wire can carry)."""
    for field in kind_fields(type(sp)):
        value = getattr(sp, field.name)
        if field.quantity is None or value is None:
            continue
        if not math.isfinite(value):
            raise SetpointRejected(f"{field.name} is not a finite number", field=field.name)
        if not field.quantity.admits(value):
            q = field.quantity
            raise SetpointRejected(
                f"{field.name} must be within {q.ge:g}..{q.le:g}",
                field=field.name,
                limit=q.le if value > q.le else q.ge,
            )


def _check_raw(local: LocalFields) -> None:
    if local.frame not in (MAV_FRAME_LOCAL_NED, MAV_FRAME_BODY_NED):
        # PX4's own words (mavlink_receiver), although MAVROS documents frames 7 and 9
        raise SetpointRejected(f"coordinate frame {local.frame} unsupported", field="frame")
    if local.type_mask & POSITION_TARGET_TYPEMASK_FORCE_SET:
        raise SetpointRejected("force not supported", field="type_mask")
    if _present(local.type_mask) == (False, False, False):
        raise SetpointRejected(
            "invalid: no position, velocity or acceleration in type_mask", field="type_mask"
        )


def _present(type_mask: int) -> tuple[bool, bool, bool]:
    """Whether any axis of position, velocity, acceleration is used."""
    return (
        type_mask & IGNORE_POSITION != IGNORE_POSITION,
        type_mask & IGNORE_VELOCITY != IGNORE_VELOCITY,
        type_mask & IGNORE_ACCELERATION != IGNORE_ACCELERATION,
    )


def _control(sp: Setpoint, local: LocalFields | None) -> Control:
    """What PX4 makes of a setpoint: for a local one, whatever its type_mask leaves in, as
    PX4's mavlink_receiver reads it, so a new local kind needs nothing here."""
    if isinstance(sp, BodyRates):
        return "rates"
    if isinstance(sp, Attitude):
        return "attitude"
    if isinstance(sp, PositionGlobal) or local is None:
        return "position"
    pos, vel, acc = _present(local.type_mask)
    if acc:
        return "acceleration"
    if local.frame == MAV_FRAME_BODY_NED:
        return "velocity"  # PX4 ignores position in BODY_NED
    if pos and vel:
        return "position_velocity"
    return "velocity" if vel else "position"


def _target_from_home(
    sp: Setpoint, local: LocalFields | None, ref: Reference
) -> tuple[float | None, float | None]:
    """(horizontal distance from home, altitude above home) of a position target, if any."""
    if isinstance(sp, PositionGlobal):
        if ref.home_lat_lon_alt is None:
            return None, sp.alt_m if sp.alt_frame == "relative" else None
        lat0, lon0, alt0 = ref.home_lat_lon_alt
        alt = {"amsl": sp.alt_m - alt0, "relative": sp.alt_m, "terrain": None}[sp.alt_frame]
        return ground_distance_m(lat0, lon0, sp.lat_deg, sp.lon_deg), alt
    if local is None or local.frame != MAV_FRAME_LOCAL_NED:
        return None, None
    # PX4 reads each position axis on its own (velocity x/y with an altitude, for one)
    mask = local.type_mask
    hn, he, hd = ref.home_ned
    horizontal = POSITION_TARGET_TYPEMASK_X_IGNORE | POSITION_TARGET_TYPEMASK_Y_IGNORE
    distance = None if mask & horizontal else math.hypot(local.x - hn, local.y - he)
    alt = None if mask & POSITION_TARGET_TYPEMASK_Z_IGNORE else -(local.z - hd)
    return distance, alt


def _velocity(sp: Setpoint, local: LocalFields | None) -> tuple[float, float] | None:
    """(horizontal, vertical) speed asked for, if the setpoint carries a velocity."""
    if local is None or local.type_mask & IGNORE_VELOCITY == IGNORE_VELOCITY:
        return None
    return math.hypot(local.vx, local.vy), abs(local.vz)


def _check_envelope(
    sp: Setpoint, local: LocalFields | None, envelope: Envelope, ref: Reference
) -> None:
    distance_m, alt_rel_m = _target_from_home(sp, local, ref)
    limits: list[tuple[str, float | None, float | None]] = [
        ("max_alt_rel_m", alt_rel_m, envelope.max_alt_rel_m),
        ("max_distance_m", distance_m, envelope.max_distance_m),
    ]
    speeds = _velocity(sp, local)
    if speeds is not None:
        limits += [
            ("max_speed_xy_m_s", speeds[0], envelope.max_speed_xy_m_s),
            ("max_speed_z_m_s", speeds[1], envelope.max_speed_z_m_s),
        ]
    for name, value, limit in limits:
        check_limit(name, value, limit, field=name)
