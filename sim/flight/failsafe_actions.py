"""PX4's failsafe actions as its parameters name them, and the mode each one flies."""

from __future__ import annotations

from enum import IntEnum

from sim.lib import modes
from sim.lib.modes import Px4Mode


class ObLossAction(IntEnum):
    """COM_OBL_RC_ACT values."""

    POSITION = 0
    ALTITUDE = 1
    STABILIZED = 2
    RETURN = 3
    LAND = 4
    HOLD = 5
    TERMINATE = 6
    DISARM = 7


class DllAction(IntEnum):
    """NAV_DLL_ACT values (GCS datalink loss)."""

    DISABLED = 0
    HOLD = 1
    RETURN = 2
    LAND = 3
    TERMINATE = 5
    DISARM = 6


class RclAction(IntEnum):
    """NAV_RCL_ACT values (manual control loss; default 2 Return)."""

    HOLD = 1
    RETURN = 2
    LAND = 3
    TERMINATE = 5
    DISARM = 6


# The mode a failsafe action flies, by the action's name in COM_OBL_RC_ACT and NAV_DLL_ACT
# (the two parameters name the same actions with different numbers).
_FAILSAFE_ACTION_MODES: dict[str, Px4Mode] = {
    "POSITION": modes.POSCTL,
    "ALTITUDE": modes.ALTCTL,
    "STABILIZED": modes.STABILIZED,
    "RETURN": modes.AUTO_RTL,
    "LAND": modes.AUTO_LAND,
    "HOLD": modes.AUTO_LOITER,
    "TERMINATE": modes.TERMINATION,
}


def failsafe_mode(actions: type[IntEnum], value: int) -> Px4Mode | None:
    """The mode of a parameter's action value; None for a value the parameter lacks."""
    try:
        name = actions(value).name
    except ValueError:
        return None
    return _FAILSAFE_ACTION_MODES.get(name)
