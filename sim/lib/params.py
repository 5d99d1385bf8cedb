"""The simulated vehicle's parameter store, with PX4 names, defaults and types.

PX4 sends every parameter in PARAM_VALUE's float field; an INT32 parameter's bits are
copied into that float unchanged ("bytewise" encoding), so clients must decode by
param_type. A Python int default marks an INT32 parameter, a float a REAL32 one.
"""

from __future__ import annotations

import functools
import json
import math
import struct
from collections.abc import Callable, Iterator, Mapping
from importlib import resources
from typing import Protocol

MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9

# PX4 defaults of the parameters the commander, navigator and streams read.
PX4_DEFAULTS: dict[str, float | int] = {
    # commander
    "COM_OF_LOSS_T": 1.0,
    "COM_OBL_RC_ACT": 0,
    "COM_DISARM_PRFLT": 10.0,
    "COM_DISARM_LAND": 2.0,
    "COM_DL_LOSS_T": 10,
    "NAV_DLL_ACT": 0,
    "NAV_RCL_ACT": 2,
    "COM_RC_IN_MODE": 1,
    "COM_RCL_EXCEPT": 0,
    "COM_RC_OVERRIDE": 1,
    "COM_RC_LOSS_T": 0.5,
    "COM_FAIL_ACT_T": 5.0,
    "COM_ARM_WO_GPS": 1,
    "COM_LOW_BAT_ACT": 3,
    "COM_SPOOLUP_TIME": 1.0,
    "GF_ACTION": 2,
    "GF_MAX_HOR_DIST": 0.0,
    "GF_MAX_VER_DIST": 0.0,
    # navigator
    "MIS_TAKEOFF_ALT": 2.5,
    "NAV_ACC_RAD": 10.0,
    "NAV_MC_ALT_RAD": 0.8,
    "NAV_LOITER_RAD": 80.0,
    "RTL_RETURN_ALT": 60.0,
    "RTL_DESCEND_ALT": 30.0,
    "RTL_LAND_DELAY": 0.0,
    "RTL_MIN_DIST": 10.0,
    "RTL_TYPE": 0,
    "VT_B_DEC_MSS": 2.0,
    # multicopter position control used by the navigator
    "MPC_TKO_SPEED": 1.5,
    "MPC_TKO_RAMP_T": 3.0,
    "MPC_LAND_SPEED": 0.7,
    "MPC_LAND_ALT1": 10.0,
    "MPC_LAND_ALT2": 5.0,
    "MPC_LAND_ALT3": 1.0,
    "MPC_LAND_CRWL": 0.3,
    "MPC_Z_VEL_MAX_DN": 1.5,
    "MPC_Z_VEL_MAX_UP": 3.0,
    "MPC_XY_CRUISE": 5.0,
    "MPC_XY_VEL_MAX": 12.0,
    "MPC_THR_HOVER": 0.5,
    # land detector (multicopter)
    "LNDMC_TRIG_TIME": 1.0,
    "LNDMC_Z_VEL_MAX": 0.25,
    "LNDMC_XY_VEL_MAX": 1.5,
    "LNDMC_ROT_MAX": 20.0,
    # manual flight tasks (sticks)
    "MPC_VEL_MANUAL": 10.0,
    "MPC_XY_MAN_EXPO": 0.6,
    "MPC_Z_MAN_EXPO": 0.6,
    "MPC_YAW_EXPO": 0.6,
    "MPC_HOLD_DZ": 0.1,
    "MPC_HOLD_MAX_XY": 0.8,
    "MPC_HOLD_MAX_Z": 0.6,
    "MPC_MAN_Y_MAX": 150.0,
    "MPC_MAN_TILT_MAX": 35.0,
    "MPC_MANTHR_MIN": 0.08,
    "MPC_THR_MAX": 1.0,
    # battery (SITL battery simulator)
    "BAT1_N_CELLS": 4,
    "BAT1_V_CHARGED": 4.05,
    "BAT1_V_EMPTY": 3.6,
    "BAT1_CAPACITY": -1.0,
    "SIM_BAT_MIN_PCT": 50.0,
    "SIM_BAT_ENABLE": 1,
    # identity
    "MAV_SYS_ID": 1,
    "MAV_COMP_ID": 1,
    "MAV_TYPE": 2,
    "SYS_AUTOSTART": 1100,
    "SYS_HITL": 0,
}

# PX4 SITL's startup files set per vehicle type (ROMFS rc.mc_defaults, rc.vtol_defaults and
# rc.fw_defaults, then the SIH airframe files 10040_sihsim_quadx, 10043_sihsim_standard_vtol
# and 10041_sihsim_airplane); rcS's SITL values (COM_RC_IN_MODE 1, COM_LOW_BAT_ACT 3) are
# in PX4_DEFAULTS above, as every SITL vehicle starts with them.
_MC_DEFAULTS: dict[str, float | int] = {
    "NAV_ACC_RAD": 2.0, "RTL_RETURN_ALT": 30.0, "RTL_DESCEND_ALT": 10.0,
    "MIS_TAKEOFF_ALT": 2.5, "SYS_AUTOSTART": 1100,
}
AIRFRAME_OVERRIDES: dict[str, dict[str, float | int]] = {
    "quad": _MC_DEFAULTS,
    "hexa": _MC_DEFAULTS,
    "octo": _MC_DEFAULTS,
    "plane": {
        "MIS_TAKEOFF_ALT": 25.0, "RTL_RETURN_ALT": 100.0, "RTL_DESCEND_ALT": 100.0,
        "RTL_LAND_DELAY": -1.0, "RTL_TYPE": 1, "NAV_ACC_RAD": 10.0, "COM_DISARM_PRFLT": -1.0,
        "FW_THR_TRIM": 0.6, "SYS_AUTOSTART": 1101,
    },
    "vtol": {
        "MIS_TAKEOFF_ALT": 20.0, "RTL_RETURN_ALT": 60.0, "RTL_TYPE": 1,
        "MPC_ACC_HOR_MAX": 2.0, "MPC_VEL_MANUAL": 5.0, "MPC_XY_VEL_MAX": 8.0,
        "MC_ROLL_P": 5.0, "MC_PITCH_P": 5.0, "MC_ROLLRATE_MAX": 120.0, "MC_YAW_P": 2.0,
        "MC_YAWRATE_MAX": 120.0, "MPC_MAN_Y_MAX": 60.0,
        "FW_AIRSPD_MIN": 7.0, "FW_AIRSPD_TRIM": 10.0, "FW_AIRSPD_MAX": 12.0,
        "SYS_AUTOSTART": 1103,
    },
    "rover": {"SYS_AUTOSTART": 1100},
}


# The values a fresh PX4 v1.16 SITL vehicle reports for the MPC_, NAV_, RTL_, COM_, MIS_ and
# LNDMC_ families (sim/data/px4_sitl_params.json, written by tools/px4_param_data.py from
# the SIH quad, standard VTOL and airplane): scripts read and set them. The airframes
# without a PX4 SIH counterpart take the quad's.
_SITL_VALUES_FOR = {"vtol": "vtol", "plane": "plane"}


@functools.cache
def _sitl_values() -> dict[str, dict[str, float | int]]:
    text = resources.files("sim").joinpath("data/px4_sitl_params.json").read_text()
    loaded: dict[str, dict[str, float | int]] = json.loads(text)
    return loaded


def sitl_family_values(airframe: str) -> dict[str, float | int]:
    return dict(_sitl_values()[_SITL_VALUES_FOR.get(airframe, "quad")])


# PX4's airplane runs no mc_pos_control nor multicopter land detector, so of the MPC_ and
# LNDMC_ families it has only the few MPC_ its shared trajectory code reads: the others are
# not its parameters; the sim's shared code (navigator, land detector, sticks) reads their
# PX4 defaults on the plane as fixed values.
_MULTICOPTER_FAMILIES = ("MPC_", "LNDMC_")


def _absent_on(airframe: str, merged: Mapping[str, float | int]) -> list[str]:
    if airframe != "plane":
        return []
    recorded = _sitl_values()["plane"]
    return [
        name for name in merged
        if name.startswith(_MULTICOPTER_FAMILIES) and name not in recorded
    ]


# PX4 SITL sets a parameter at start from the variable PX4_PARAM_<name> (rcS).
ENV_PARAM_PREFIX = "PX4_PARAM_"

class ParamReader(Protocol):
    """Read access to current parameter values; integers come back as float."""

    def get(self, name: str) -> float: ...


def param_or(params: ParamReader | None, name: str, default: float) -> float:
    """A parameter's current value, or the PX4 default given when there is no store."""
    return default if params is None else float(params.get(name))


def encode_param_value(value: float | int, param_type: int) -> float:
    """The float PX4 puts in PARAM_VALUE.param_value: INT32 bits copied, REAL32 as is."""
    if param_type == MAV_PARAM_TYPE_INT32:
        packed: float = struct.unpack("<f", struct.pack("<i", int(value)))[0]
        return packed
    return float(value)


def decode_param_value(wire_value: float, param_type: int) -> float | int:
    """Inverse of encode_param_value."""
    if param_type == MAV_PARAM_TYPE_INT32:
        decoded: int = struct.unpack("<i", struct.pack("<f", wire_value))[0]
        return decoded
    return float(struct.unpack("<f", struct.pack("<f", wire_value))[0])


class ParamStore:
    """Named parameters with a fixed order (PARAM_VALUE.param_index) and a type each.

    Implements the airframes' ParamReader protocol (`get` returns a float). Changes take
    effect at once: every reader calls `get` when it needs the value.
    """

    def __init__(
        self,
        defaults: Mapping[str, float | int],
        fixed: Mapping[str, float | int] | None = None,
    ) -> None:
        self._values: dict[str, float | int] = dict(sorted(defaults.items()))
        self._names = list(self._values)
        self._index = {name: i for i, name in enumerate(self._names)}
        self._listeners: list[Callable[[str, float | int], None]] = []
        # values the shared code reads that this airframe has no parameter for: constants
        # of the sim, never listed, read or set over MAVLink
        self._fixed: dict[str, float | int] = {
            name: value for name, value in (fixed or {}).items() if name not in self._values
        }

    @classmethod
    def for_airframe(
        cls, airframe: str, airframe_defaults: Mapping[str, float | int]
    ) -> ParamStore:
        merged: dict[str, float | int] = dict(PX4_DEFAULTS)
        merged.update(sitl_family_values(airframe))
        merged.update(airframe_defaults)
        merged.update(AIRFRAME_OVERRIDES.get(airframe, {}))
        absent = {name: merged.pop(name) for name in _absent_on(airframe, merged)}
        return cls(merged, fixed=absent)

    def __contains__(self, name: object) -> bool:
        return name in self._values

    def __len__(self) -> int:
        return len(self._names)

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def get(self, name: str) -> float:
        value = self._values.get(name)
        if value is None:
            value = self._fixed[name]
        return float(value)

    def value(self, name: str) -> float | int:
        """The value with its own type (int for INT32)."""
        return self._values[name]

    def param_type(self, name: str) -> int:
        is_int = isinstance(self._values[name], int)
        return MAV_PARAM_TYPE_INT32 if is_int else MAV_PARAM_TYPE_REAL32

    def index(self, name: str) -> int:
        return self._index[name]

    def name_at(self, index: int) -> str | None:
        return self._names[index] if 0 <= index < len(self._names) else None

    def set(self, name: str, value: float) -> float | int:
        """Store a value in the parameter's own type; returns what was stored."""
        is_int = self.param_type(name) == MAV_PARAM_TYPE_INT32
        stored: float | int = int(value) if is_int else float(value)
        self._values[name] = stored
        for listener in self._listeners:
            listener(name, stored)
        return stored

    def set_from_wire(self, name: str, wire_value: float) -> float | int:
        """PARAM_SET: decode by the parameter's own type, as PX4 does."""
        return self.set(name, decode_param_value(wire_value, self.param_type(name)))

    def set_from_environment(self, environ: Mapping[str, str]) -> list[str]:
        """PX4 SITL's overrides at start (its rcS: ``export PX4_PARAM_{name}={value}``, then
        ``param set`` for each): every such variable naming a parameter of this vehicle sets
        it, as a number of the parameter's own type. Returns what could not be set (a name
        the vehicle lacks, a value that is no number; PX4 says so and starts anyway)."""
        problems = []
        for variable, text in sorted(environ.items()):
            if not variable.startswith(ENV_PARAM_PREFIX):
                continue
            name = variable.removeprefix(ENV_PARAM_PREFIX)
            if name not in self._index:
                problems.append(f"{variable}: this vehicle has no parameter {name}")
                continue
            if name == "MAV_SYS_ID":
                problems.append(f"{variable}: the system id follows the instance (--instance)")
                continue
            try:
                number = float(text) if self.param_type(name) != MAV_PARAM_TYPE_INT32 else int(text)
            except ValueError:
                problems.append(f"{variable}: {text!r} is not a number for {name}")
                continue
            if not math.isfinite(number):
                problems.append(f"{variable}: {text!r} is not a finite number")
                continue
            self.set(name, number)
        return problems

    def wire_value(self, name: str) -> float:
        return encode_param_value(self._values[name], self.param_type(name))

    def on_change(self, listener: Callable[[str, float | int], None]) -> None:
        self._listeners.append(listener)
