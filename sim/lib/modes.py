"""PX4 flight modes as they appear on MAVLink: custom_mode, base_mode and their names.

PX4 packs its mode as `main_mode << 16 | sub_mode << 24` into HEARTBEAT.custom_mode
(px4_custom_mode.h); base_mode carries the MAV_MODE_FLAG bits for the mode's family.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_AUTO_ENABLED = 4
MAV_MODE_FLAG_GUIDED_ENABLED = 8
MAV_MODE_FLAG_STABILIZE_ENABLED = 16
MAV_MODE_FLAG_MANUAL_INPUT_ENABLED = 64
MAV_MODE_FLAG_SAFETY_ARMED = 128


class MainMode(IntEnum):
    """PX4_CUSTOM_MAIN_MODE."""

    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7
    RATTITUDE = 8
    TERMINATION = 10


class AutoSubMode(IntEnum):
    """PX4_CUSTOM_SUB_MODE_AUTO."""

    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6
    FOLLOW_TARGET = 8
    PRECLAND = 9
    VTOL_TAKEOFF = 10


class PosctlSubMode(IntEnum):
    """PX4_CUSTOM_SUB_MODE_POSCTL."""

    POSCTL = 0
    ORBIT = 1
    SLOW = 2


class MavStandardMode(IntEnum):
    """MAV_STANDARD_MODE, as CURRENT_MODE.standard_mode."""

    NON_STANDARD = 0
    POSITION_HOLD = 1
    ORBIT = 2
    CRUISE = 3
    ALTITUDE_HOLD = 4
    SAFE_RECOVERY = 5
    MISSION = 6
    LAND = 7
    TAKEOFF = 8


@dataclass(frozen=True)
class Px4Mode:
    """One PX4 mode: a main mode and, for AUTO and POSCTL, a sub mode."""

    main: int
    sub: int = 0

    @property
    def custom_mode(self) -> int:
        return (self.main << 16) | (self.sub << 24)

    @property
    def name(self) -> str:
        return MODE_NAMES.get(self, f"UNKNOWN_{self.main}_{self.sub}")

    @property
    def standard_mode(self) -> MavStandardMode:
        return _STANDARD_MODES.get(self, MavStandardMode.NON_STANDARD)

    def base_mode(self, armed: bool) -> int:
        flags = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | _FAMILY_FLAGS.get(self.main, 0)
        if armed:
            flags |= MAV_MODE_FLAG_SAFETY_ARMED
        return flags


def decode_custom_mode(custom_mode: int) -> Px4Mode:
    """The mode in a HEARTBEAT.custom_mode; POSCTL/AUTO keep their sub mode, others drop it."""
    main = (custom_mode >> 16) & 0xFF
    sub = (custom_mode >> 24) & 0xFF
    if main not in (MainMode.AUTO, MainMode.POSCTL):
        sub = 0
    return Px4Mode(main, sub)


MANUAL = Px4Mode(MainMode.MANUAL)
ALTCTL = Px4Mode(MainMode.ALTCTL)
POSCTL = Px4Mode(MainMode.POSCTL, PosctlSubMode.POSCTL)
ORBIT = Px4Mode(MainMode.POSCTL, PosctlSubMode.ORBIT)
ACRO = Px4Mode(MainMode.ACRO)
OFFBOARD = Px4Mode(MainMode.OFFBOARD)
STABILIZED = Px4Mode(MainMode.STABILIZED)
TERMINATION = Px4Mode(MainMode.TERMINATION)
AUTO_READY = Px4Mode(MainMode.AUTO, AutoSubMode.READY)
AUTO_TAKEOFF = Px4Mode(MainMode.AUTO, AutoSubMode.TAKEOFF)
AUTO_LOITER = Px4Mode(MainMode.AUTO, AutoSubMode.LOITER)
AUTO_MISSION = Px4Mode(MainMode.AUTO, AutoSubMode.MISSION)
AUTO_RTL = Px4Mode(MainMode.AUTO, AutoSubMode.RTL)
AUTO_LAND = Px4Mode(MainMode.AUTO, AutoSubMode.LAND)
AUTO_FOLLOW_TARGET = Px4Mode(MainMode.AUTO, AutoSubMode.FOLLOW_TARGET)
AUTO_PRECLAND = Px4Mode(MainMode.AUTO, AutoSubMode.PRECLAND)
AUTO_VTOL_TAKEOFF = Px4Mode(MainMode.AUTO, AutoSubMode.VTOL_TAKEOFF)

MODE_NAMES: dict[Px4Mode, str] = {
    MANUAL: "MANUAL",
    ALTCTL: "ALTCTL",
    POSCTL: "POSCTL",
    ORBIT: "ORBIT",
    Px4Mode(MainMode.POSCTL, PosctlSubMode.SLOW): "POSITION_SLOW",
    ACRO: "ACRO",
    OFFBOARD: "OFFBOARD",
    STABILIZED: "STABILIZED",
    Px4Mode(MainMode.RATTITUDE): "RATTITUDE",
    TERMINATION: "TERMINATION",
    AUTO_READY: "AUTO_READY",
    AUTO_TAKEOFF: "AUTO_TAKEOFF",
    AUTO_LOITER: "AUTO_LOITER",
    AUTO_MISSION: "AUTO_MISSION",
    AUTO_RTL: "AUTO_RTL",
    AUTO_LAND: "AUTO_LAND",
    AUTO_FOLLOW_TARGET: "AUTO_FOLLOW_TARGET",
    AUTO_PRECLAND: "AUTO_PRECLAND",
    AUTO_VTOL_TAKEOFF: "AUTO_VTOL_TAKEOFF",
}

# Modes PX4 can also name with a MAV_STANDARD_MODE (CURRENT_MODE.standard_mode).
_STANDARD_MODES: dict[Px4Mode, MavStandardMode] = {
    POSCTL: MavStandardMode.POSITION_HOLD,
    ORBIT: MavStandardMode.ORBIT,
    ALTCTL: MavStandardMode.ALTITUDE_HOLD,
    AUTO_RTL: MavStandardMode.SAFE_RECOVERY,
    AUTO_MISSION: MavStandardMode.MISSION,
    AUTO_LAND: MavStandardMode.LAND,
    AUTO_TAKEOFF: MavStandardMode.TAKEOFF,
}

_MANUAL_FAMILY = MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | MAV_MODE_FLAG_STABILIZE_ENABLED
_AUTO_FAMILY = (
    MAV_MODE_FLAG_AUTO_ENABLED | MAV_MODE_FLAG_GUIDED_ENABLED | MAV_MODE_FLAG_STABILIZE_ENABLED
)
_FAMILY_FLAGS: dict[int, int] = {
    MainMode.MANUAL: MAV_MODE_FLAG_MANUAL_INPUT_ENABLED,
    MainMode.ACRO: MAV_MODE_FLAG_MANUAL_INPUT_ENABLED,
    MainMode.STABILIZED: _MANUAL_FAMILY,
    MainMode.RATTITUDE: _MANUAL_FAMILY,
    MainMode.ALTCTL: _MANUAL_FAMILY,
    MainMode.POSCTL: _MANUAL_FAMILY | MAV_MODE_FLAG_GUIDED_ENABLED,
    MainMode.AUTO: _AUTO_FAMILY,
    MainMode.OFFBOARD: _AUTO_FAMILY,
    MainMode.TERMINATION: 0,
}

# Modes the simulated vehicle can fly; the others are known names PX4 refuses here
# (no mission stored, no follow target, no precision-landing beacon).
FLYABLE_MODES = frozenset(
    {
        MANUAL,
        ALTCTL,
        POSCTL,
        ACRO,
        STABILIZED,
        OFFBOARD,
        TERMINATION,
        AUTO_TAKEOFF,
        AUTO_LOITER,
        AUTO_RTL,
        AUTO_LAND,
        AUTO_VTOL_TAKEOFF,
    }
)
