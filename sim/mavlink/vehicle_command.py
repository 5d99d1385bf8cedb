"""What the simulated vehicle does with a vehicle_command (COMMAND_LONG / COMMAND_INT),
after PX4's Commander::handle_command and the navigator's command handling.

Each handler returns the MAV_RESULT to ack, or None when PX4 leaves the command
unanswered (or has already answered it itself).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import development as mavlink

from sim.flight.commander import (
    ARM_DISARM_FORCE_MAGIC,
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_DENIED,
    MAV_RESULT_TEMPORARILY_REJECTED,
    MAV_RESULT_UNSUPPORTED,
)
from sim.flight.commander_events import send_command_decision
from sim.flight.commander_failsafe import MAV_SEVERITY_CRITICAL, MAV_SEVERITY_INFO
from sim.lib import modes
from sim.lib.geo import MAVLINK_ALT_LIMIT_M, is_valid_lat_lon
from sim.lib.modes import Px4Mode
from sim.mavlink.vehicle_interface import Link, Message, VehicleInterface

MAV_DO_REPOSITION_FLAGS_CHANGE_MODE = 1
VTOL_TRANSITION_MC = 3
VTOL_TRANSITION_FW = 4

# MC→FW transition is refused while the navigator flies these.
_NO_FRONT_TRANSITION_MODES = frozenset(
    {modes.AUTO_TAKEOFF, modes.AUTO_VTOL_TAKEOFF, modes.AUTO_LAND, modes.AUTO_RTL, modes.ORBIT}
)


@dataclass
class Command:
    """A COMMAND_LONG or COMMAND_INT with COMMAND_LONG's float params."""

    command: int
    params: list[float]
    frame: int
    is_int: bool
    source_system: int
    source_component: int


CommandHandler = Callable[[Command, Link], int | None]


def as_int(value: float) -> int:
    """A command param as an integer; NaN (\"unset\") and infinities count as -1."""
    return int(value) if math.isfinite(value) else -1


def command_ack(cmd: Command, result: int) -> Message:
    return mavlink.MAVLink_command_ack_message(
        cmd.command, result, 0, 0, cmd.source_system, cmd.source_component)


class VehicleCommands:
    """Arming, modes, takeoff/land/return, reposition, VTOL transition and home."""

    def __init__(self, vehicle: VehicleInterface) -> None:
        self._v = vehicle
        self.handlers: dict[int, CommandHandler] = {
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM: self._arm_disarm,
            mavlink.MAV_CMD_DO_SET_MODE: self._do_set_mode,
            mavlink.MAV_CMD_NAV_TAKEOFF: self._takeoff,
            mavlink.MAV_CMD_NAV_LAND: self._land,
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: self._rtl,
            mavlink.MAV_CMD_DO_REPOSITION: self._reposition,
            mavlink.MAV_CMD_DO_VTOL_TRANSITION: self._vtol_transition,
            mavlink.MAV_CMD_DO_SET_HOME: self._set_home,
            mavlink.MAV_CMD_RUN_PREARM_CHECKS: self._run_prearm_checks,
        }

    def set_mode(self, base_mode: int, main_mode: int, sub_mode: int) -> int:
        """DO_SET_MODE and SET_MODE: the MAV_RESULT of the mode request."""
        if not base_mode & modes.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return MAV_RESULT_TEMPORARILY_REJECTED
        mode = Px4Mode(main_mode, sub_mode if main_mode in (modes.MainMode.AUTO,
                                                             modes.MainMode.POSCTL) else 0)
        return self._v.commander.request_mode(mode)

    def _arm_disarm(self, cmd: Command, link: Link) -> int | None:
        action = cmd.params[0]
        force = as_int(cmd.params[1]) == ARM_DISARM_FORCE_MAGIC
        if action == 1.0:
            return self._v.commander.arm(self._v.now_s)
        if action == 0.0:
            return self._v.commander.disarm(force)
        return None  # PX4 leaves any other param1 unanswered

    def _do_set_mode(self, cmd: Command, link: Link) -> int | None:
        # PX4 v1.16 acks every DO_SET_MODE twice: ACCEPTED at once, then the real result.
        link.send(command_ack(cmd, MAV_RESULT_ACCEPTED))
        return self.set_mode(*(as_int(p) for p in cmd.params[:3]))

    def _takeoff(self, cmd: Command, link: Link) -> int:
        """Commander's NAV_TAKEOFF is a mode change: taken at once while disarmed, ready or
        not (UserModeIntention::change), so a takeoff before the vehicle is ready is refused
        by the arming that follows, with its reasons; armed, only when TAKEOFF can run."""
        v = self._v
        if v.airframe_name == "rover":
            return MAV_RESULT_TEMPORARILY_REJECTED
        v.navigator.request_takeoff(cmd.params[6])
        return v.commander.request_mode(modes.AUTO_TAKEOFF)

    def _run_prearm_checks(self, cmd: Command, link: Link) -> int:
        return self._v.commander.report_checks()

    def _land(self, cmd: Command, link: Link) -> int:
        self._v.commander.switch_mode(modes.AUTO_LAND)
        self._v.announce(MAV_SEVERITY_INFO, "Landing at current position")
        send_command_decision(self._v.commander.events, "commander_landing_current_pos")
        return MAV_RESULT_ACCEPTED

    def _rtl(self, cmd: Command, link: Link) -> int:
        result = self._v.commander.request_mode(modes.AUTO_RTL)
        if result == MAV_RESULT_ACCEPTED:
            self._v.announce(MAV_SEVERITY_INFO, "Returning to launch")
            send_command_decision(self._v.commander.events, "commander_rtl")
        return result

    def _reposition(self, cmd: Command, link: Link) -> int:
        v = self._v
        speed, flags, _radius, yaw, lat, lon, alt = cmd.params
        if as_int(flags) != MAV_DO_REPOSITION_FLAGS_CHANGE_MODE:
            return MAV_RESULT_UNSUPPORTED
        if not v.ready:
            return MAV_RESULT_TEMPORARILY_REJECTED
        current = v.truth.position_ned_m
        target = list(current)
        if math.isfinite(lat) and math.isfinite(lon):
            north, east, _ = v.origin.to_ned(lat, lon, v.origin.alt_m)
            target[0], target[1] = north, east
        if math.isfinite(alt):
            target[2] = self._down_of_alt(alt, cmd.frame)
        if not v.within_geofence(target):
            return MAV_RESULT_DENIED
        yaw_rad = yaw if math.isfinite(yaw) else math.nan
        speed_m_s = speed if math.isfinite(speed) and speed > 0 else math.nan
        v.navigator.request_reposition(target, yaw_rad, speed_m_s)
        v.commander.switch_mode(modes.AUTO_LOITER)
        return MAV_RESULT_ACCEPTED

    def _down_of_alt(self, alt_m: float, frame: int) -> float:
        """Local down of an altitude in a command's frame (AMSL unless relative)."""
        relative_frames = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                           mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
        if frame in relative_frames:
            return self._v.commander.home.position_ned_m[2] - alt_m
        return self._v.origin.down_of_altitude(alt_m)

    def _vtol_transition(self, cmd: Command, link: Link) -> int | None:
        v = self._v
        if not v.model.is_vtol:
            return None  # PX4 without a VTOL attitude controller leaves it unanswered
        state = as_int(cmd.params[0])
        immediate = as_int(cmd.params[1]) == 1
        if state == VTOL_TRANSITION_FW:
            if v.commander.nav_mode in _NO_FRONT_TRANSITION_MODES:
                return MAV_RESULT_TEMPORARILY_REJECTED
            v.model.request_transition(to_fixed_wing=True, immediate=immediate)
            return MAV_RESULT_ACCEPTED
        if state == VTOL_TRANSITION_MC:
            v.model.request_transition(to_fixed_wing=False, immediate=immediate)
            return MAV_RESULT_ACCEPTED
        return MAV_RESULT_DENIED

    def _set_home(self, cmd: Command, link: Link) -> int:
        v = self._v
        if not v.ready:
            return MAV_RESULT_TEMPORARILY_REJECTED
        if cmd.params[0] == 1.0:
            v.set_home_here()
            return MAV_RESULT_ACCEPTED
        lat, lon, alt = cmd.params[4], cmd.params[5], cmd.params[6]
        if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(alt)):
            return MAV_RESULT_DENIED
        # PX4 takes any finite point; one off the globe or beyond what HOME_POSITION
        # carries would have no place in the local frame, so it is refused with a reason
        if not is_valid_lat_lon(lat, lon) or abs(alt) > MAVLINK_ALT_LIMIT_M:
            v.announce(MAV_SEVERITY_CRITICAL,
                       f"Home not set: {lat:.7f}, {lon:.7f}, {alt:.1f} m out of range")
            return MAV_RESULT_DENIED
        # PX4's commander: param4 is the home yaw in degrees, NaN keeps it
        v.set_home_at(lat, lon, alt, math.radians(cmd.params[3]))
        return MAV_RESULT_ACCEPTED
