"""PX4 flight mode codec: mode names <-> (main_mode, sub_mode) <-> custom_mode.

PX4 packs its mode into HEARTBEAT.custom_mode as ``main << 16 | sub << 24``
(px4_custom_mode.h); DO_SET_MODE carries main and sub as param2 and param3.
"""

from __future__ import annotations

from types import MappingProxyType

PX4_CUSTOM_MAIN_MODE_MANUAL = 1
PX4_CUSTOM_MAIN_MODE_ALTCTL = 2
PX4_CUSTOM_MAIN_MODE_POSCTL = 3
PX4_CUSTOM_MAIN_MODE_AUTO = 4
PX4_CUSTOM_MAIN_MODE_ACRO = 5
PX4_CUSTOM_MAIN_MODE_OFFBOARD = 6
PX4_CUSTOM_MAIN_MODE_STABILIZED = 7
PX4_CUSTOM_MAIN_MODE_RATTITUDE = 8
PX4_CUSTOM_MAIN_MODE_TERMINATION = 10

PX4_CUSTOM_SUB_MODE_AUTO_READY = 1
PX4_CUSTOM_SUB_MODE_AUTO_TAKEOFF = 2
PX4_CUSTOM_SUB_MODE_AUTO_LOITER = 3
PX4_CUSTOM_SUB_MODE_AUTO_MISSION = 4
PX4_CUSTOM_SUB_MODE_AUTO_RTL = 5
PX4_CUSTOM_SUB_MODE_AUTO_LAND = 6
PX4_CUSTOM_SUB_MODE_AUTO_FOLLOW_TARGET = 8
PX4_CUSTOM_SUB_MODE_AUTO_PRECLAND = 9
PX4_CUSTOM_SUB_MODE_AUTO_VTOL_TAKEOFF = 10
PX4_CUSTOM_SUB_MODE_POSCTL_POSCTL = 0
PX4_CUSTOM_SUB_MODE_POSCTL_ORBIT = 1

MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 128

_MODES: dict[str, tuple[int, int]] = {
    "MANUAL": (PX4_CUSTOM_MAIN_MODE_MANUAL, 0),
    "ALTCTL": (PX4_CUSTOM_MAIN_MODE_ALTCTL, 0),
    "POSCTL": (PX4_CUSTOM_MAIN_MODE_POSCTL, PX4_CUSTOM_SUB_MODE_POSCTL_POSCTL),
    "POSCTL_ORBIT": (PX4_CUSTOM_MAIN_MODE_POSCTL, PX4_CUSTOM_SUB_MODE_POSCTL_ORBIT),
    "ACRO": (PX4_CUSTOM_MAIN_MODE_ACRO, 0),
    "STABILIZED": (PX4_CUSTOM_MAIN_MODE_STABILIZED, 0),
    "OFFBOARD": (PX4_CUSTOM_MAIN_MODE_OFFBOARD, 0),
    "HOLD": (PX4_CUSTOM_MAIN_MODE_AUTO, PX4_CUSTOM_SUB_MODE_AUTO_LOITER),
    "TAKEOFF": (PX4_CUSTOM_MAIN_MODE_AUTO, PX4_CUSTOM_SUB_MODE_AUTO_TAKEOFF),
    "LAND": (PX4_CUSTOM_MAIN_MODE_AUTO, PX4_CUSTOM_SUB_MODE_AUTO_LAND),
    "RTL": (PX4_CUSTOM_MAIN_MODE_AUTO, PX4_CUSTOM_SUB_MODE_AUTO_RTL),
    "MISSION": (PX4_CUSTOM_MAIN_MODE_AUTO, PX4_CUSTOM_SUB_MODE_AUTO_MISSION),
    "FOLLOW_TARGET": (PX4_CUSTOM_MAIN_MODE_AUTO, PX4_CUSTOM_SUB_MODE_AUTO_FOLLOW_TARGET),
    "PRECLAND": (PX4_CUSTOM_MAIN_MODE_AUTO, PX4_CUSTOM_SUB_MODE_AUTO_PRECLAND),
    "VTOL_TAKEOFF": (PX4_CUSTOM_MAIN_MODE_AUTO, PX4_CUSTOM_SUB_MODE_AUTO_VTOL_TAKEOFF),
    "TERMINATION": (PX4_CUSTOM_MAIN_MODE_TERMINATION, 0),
    "RATTITUDE": (PX4_CUSTOM_MAIN_MODE_RATTITUDE, 0),
    "READY": (PX4_CUSTOM_MAIN_MODE_AUTO, PX4_CUSTOM_SUB_MODE_AUTO_READY),
}

PX4_MODE_NAMES: tuple[str, ...] = tuple(_MODES)
"""Every mode name the codec knows, in PX4's order."""

MODE_BY_NAME = MappingProxyType(_MODES)
_NAME_BY_MODE = {main_sub: name for name, main_sub in _MODES.items()}


class UnknownModeError(ValueError):
    """A mode name that is not in PX4_MODE_NAMES."""


def main_sub_from_name(name: str) -> tuple[int, int]:
    try:
        return _MODES[name.upper()]
    except KeyError:
        raise UnknownModeError(f"unknown PX4 mode {name!r}") from None


def custom_mode_from_name(name: str) -> int:
    main, sub = main_sub_from_name(name)
    return main << 16 | sub << 24


def main_sub_from_custom_mode(custom_mode: int) -> tuple[int, int]:
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


def name_from_main_sub(main: int, sub: int) -> str:
    """Mode name; modes without sub-modes ignore sub, unknown ones read ``MAIN_m_SUB_s``."""
    name = _NAME_BY_MODE.get((main, sub)) or _NAME_BY_MODE.get((main, 0))
    if name is None or (main == PX4_CUSTOM_MAIN_MODE_AUTO and (main, sub) not in _NAME_BY_MODE):
        return f"MAIN_{main}_SUB_{sub}"
    return name


def name_from_custom_mode(custom_mode: int) -> str:
    return name_from_main_sub(*main_sub_from_custom_mode(custom_mode))


def set_mode_base_mode(armed: bool) -> int:
    """DO_SET_MODE param1: PX4 needs the custom bit; the armed bit mirrors the current state."""
    return MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
