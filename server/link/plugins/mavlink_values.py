"""MAVLink field values in the state's units and names: enum and flag names, battery, PWM."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import development as mavlink

from server.link.core import state

# MAVLink renamed these VTOL types in 2024; pymavlink's generated enum still carries the
# old reserved names, and a dashboard should show what the vehicle is.
_RENAMED = {
    ("MAV_TYPE", 19): "MAV_TYPE_VTOL_TAILSITTER_DUOROTOR",
    ("MAV_TYPE", 20): "MAV_TYPE_VTOL_TAILSITTER_QUADROTOR",
    ("MAV_TYPE", 22): "MAV_TYPE_VTOL_FIXEDROTOR",
    ("MAV_TYPE", 23): "MAV_TYPE_VTOL_TAILSITTER",
    ("MAV_TYPE", 24): "MAV_TYPE_VTOL_TILTWING",
}


def enum_name(enum: str, value: int, prefix: str) -> str:
    renamed = _RENAMED.get((enum, value))
    if renamed is not None:
        return renamed.removeprefix(prefix)
    entry = mavlink.enums[enum].get(value)
    return entry.name.removeprefix(prefix) if entry is not None else str(value)


def flag_names(enum: str, bits: int, prefix: str) -> tuple[str, ...]:
    """The names of the set bits of a MAVLink bitmask enum, without the prefix."""
    return tuple(
        entry.name.removeprefix(prefix)
        for value, entry in sorted(mavlink.enums[enum].items())
        if value > 0 and value & (value - 1) == 0 and bits & value
    )


def finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def pwm_to_unit(pwm: float) -> float:
    """PX4 motor PWM 1000..2000 us as 0..1."""
    return min(max((pwm - 1000.0) / 1000.0, 0.0), 1.0)


def battery_state(
    voltage_v: float | None, current_ca: int, remaining_pct: int
) -> state.BatteryState:
    """MAVLink marks unknown current and remaining charge with -1."""
    return state.BatteryState(
        voltage_v,
        None if current_ca < 0 else current_ca / 100.0,
        None if remaining_pct < 0 else float(remaining_pct),
    )
