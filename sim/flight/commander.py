"""Arming, modes and failsafes of the simulated vehicle, after PX4's commander.

The commander owns three pieces of state PX4 keeps apart: whether the vehicle is armed,
the mode it flies now (`nav_mode`), and the mode the user asked for last (`user_mode`).
They differ while a failsafe holds, e.g. OFFBOARD asked, Position flown after the
offboard stream stopped; when the cause clears the vehicle returns to the user's mode.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from sim.flight import commander_events as ev
from sim.flight.commander_failsafe import (
    MAV_SEVERITY_CRITICAL,
    MAV_SEVERITY_INFO,
    Announce,
    CommanderFailsafes,
)
from sim.flight.manual_control import (
    MANUAL_CONTROL_MODES,
    ManualControlSelector,
    RcInMode,
    StickSample,
)
from sim.lib import modes
from sim.lib.events import EventLog
from sim.lib.modes import Px4Mode
from sim.lib.params import ParamReader
from sim.lib.topics import ControlSetpoint

MAV_RESULT_ACCEPTED = 0
MAV_RESULT_TEMPORARILY_REJECTED = 1
MAV_RESULT_DENIED = 2
MAV_RESULT_UNSUPPORTED = 3
MAV_RESULT_FAILED = 4

# param2 of MAV_CMD_COMPONENT_ARM_DISARM that skips the landed check on disarm.
ARM_DISARM_FORCE_MAGIC = 21196

# PX4's commander runs its checks every COMMANDER_MONITORING_INTERVAL (10 ms)
COMMANDER_MONITORING_INTERVAL_S = 0.01

# mode_requirements.cpp: modes with mode_req_prevent_arming, never kept as the mode to
# return to after disarming
_MODES_PREVENTING_ARMING = frozenset({
    modes.AUTO_RTL, modes.AUTO_LAND, modes.TERMINATION, modes.AUTO_FOLLOW_TARGET,
    modes.AUTO_PRECLAND, modes.ORBIT,
})
# Commander::printRejectMode says a refused mode switch at most once a second
MODE_REJECT_PRINT_INTERVAL_S = 1.0

# Known modes the simulated vehicle cannot run at all (nothing to follow, no beacon).
_UNSUPPORTED_MODES = frozenset(
    {modes.AUTO_READY, modes.AUTO_FOLLOW_TARGET, modes.AUTO_PRECLAND, modes.ORBIT}
)


@dataclass
class Home:
    """PX4 `home_position`: where RTL returns to, in local NED and geodetic terms."""

    valid: bool = False
    position_ned_m: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    yaw_rad: float = 0.0
    lat_deg: float = math.nan
    lon_deg: float = math.nan
    alt_m: float = math.nan


@dataclass
class OffboardInput:
    """The newest offboard setpoint and when it arrived (sim time)."""

    setpoint: ControlSetpoint | None = None
    received_s: float = -math.inf


class Commander(CommanderFailsafes):
    def __init__(
        self,
        params: ParamReader,
        announce: Announce,
        *,
        is_vtol: bool = False,
        has_mission: bool = False,
    ) -> None:
        self._params = params
        self._announce = announce
        # modes that need something this vehicle may lack, and whether it has it
        self._mode_available = {modes.AUTO_MISSION: has_mission, modes.AUTO_VTOL_TAKEOFF: is_vtol}
        self.armed = False
        self.nav_mode: Px4Mode = modes.AUTO_LOITER
        self.user_mode: Px4Mode = modes.AUTO_LOITER
        self.ready = False
        self.landed = True
        self.home = Home()
        self.offboard = OffboardInput()
        self.failsafe = False
        self.armed_at_s = 0.0
        self.took_off_since_arming = False
        self._landed_since_s: float | None = None
        self._offboard_lost_since_s: float | None = None
        self._offboard_resumed_at_s: float | None = None
        self._now_s = 0.0
        self.gcs_heartbeat_s: float | None = None
        self.onboard_heartbeat_s: float | None = None
        self.datalink_lost = False
        self.mode_changes = 0
        # OFFBOARD requests still to be lost as in a race seen on PX4 v1.16: asked for just
        # as AUTO.TAKEOFF completes, OFFBOARD is acked ACCEPTED, yet the vehicle ends in Hold
        self.offboard_requests_lost = 0
        self._arm_listeners: list[Callable[[bool], None]] = []
        self.events = EventLog()
        self._reported_checks: tuple[ev.ArmingCheck, ...] | None = None
        self._checked_s = -math.inf
        self._mode_after_disarming: Px4Mode = modes.AUTO_LOITER
        self._mode_rejected_s = -math.inf
        self.manual_control = ManualControlSelector(params)
        self._manual_control_lost = True
        self._manual_control_lost_at_arming = True
        self._rc_loss_action_at_s: float | None = None
        self._rc_lost_s: float | None = None

    # -- queries -----------------------------------------------------------------------

    def offboard_signal_fresh(self, now_s: float | None = None) -> bool:
        now = self._now_s if now_s is None else now_s
        age = now - self.offboard.received_s
        return self.offboard.setpoint is not None and age <= self._params.get("COM_OF_LOSS_T")

    def manual_control_lost(self, now_s: float | None = None) -> bool:
        """No stick input in use (none yet, too old, or from a source COM_RC_IN_MODE
        does not take)."""
        return self.manual_control.current(self._now_s if now_s is None else now_s) is None

    def mode_can_run(self, mode: Px4Mode) -> bool:
        if mode == modes.OFFBOARD:
            return self.offboard_signal_fresh()
        if mode in MANUAL_CONTROL_MODES:
            # modeCheck: a mode needing manual control cannot run without it
            return not self.manual_control_lost()
        if mode in self._mode_available:
            return self._mode_available[mode]
        if mode in (modes.AUTO_RTL, modes.AUTO_TAKEOFF):
            return self.ready
        return mode not in _UNSUPPORTED_MODES

    # -- requests from MAVLink ---------------------------------------------------------

    def request_mode(self, mode: Px4Mode) -> int:
        """DO_SET_MODE / SET_MODE: the MAV_RESULT of the second (real) ack."""
        if (mode not in modes.MODE_NAMES or mode in _UNSUPPORTED_MODES
                or (self.armed and not self.mode_can_run(mode))):
            self._print_reject_mode(mode)
            return MAV_RESULT_TEMPORARILY_REJECTED
        if mode == modes.OFFBOARD and self.offboard_requests_lost > 0:
            self.offboard_requests_lost -= 1
            self.switch_mode(modes.AUTO_LOITER)
            return MAV_RESULT_ACCEPTED
        self._set_user_mode(mode)
        self._set_nav_mode(mode)
        self._clear_failsafe()
        return MAV_RESULT_ACCEPTED

    def switch_mode(self, mode: Px4Mode) -> None:
        """A mode change the vehicle makes itself and adopts as the user's (takeoff → Hold)."""
        self._set_user_mode(mode)
        self._set_nav_mode(mode)
        self._clear_failsafe()

    def arm(self, now_s: float) -> int:
        if self.armed:
            return MAV_RESULT_ACCEPTED
        if not self.can_arm():
            # PX4 names no check here: the failing ones went out before as events
            self._announce(MAV_SEVERITY_CRITICAL,
                           "Arming denied: Resolve system health failures first")
            ev.send_arm_denied(self.events)
            return MAV_RESULT_TEMPORARILY_REJECTED
        self.armed = True
        self.armed_at_s = now_s
        self._manual_control_lost_at_arming = self.manual_control_lost(now_s)
        self.took_off_since_arming = not self.landed
        self._landed_since_s = now_s if self.landed else None
        self._announce(MAV_SEVERITY_INFO,
                       f"Armed by {ev.arm_reason_text(ev.ARM_REASON_COMMAND_EXTERNAL)}")
        ev.send_armed(self.events, True, ev.ARM_REASON_COMMAND_EXTERNAL)
        self._arm_listeners_notify()
        return MAV_RESULT_ACCEPTED

    def disarm(self, force: bool) -> int:
        if not self.armed:
            return MAV_RESULT_ACCEPTED
        if not force and not self.landed:
            self._announce(MAV_SEVERITY_CRITICAL, "Disarming denied: not landed")
            ev.send_disarm_denied(self.events)
            return MAV_RESULT_TEMPORARILY_REJECTED
        self._disarm(ev.ARM_REASON_COMMAND_EXTERNAL)
        return MAV_RESULT_ACCEPTED

    def report_checks(self) -> int:
        """MAV_CMD_RUN_PREARM_CHECKS: the check report again, changed or not (a ground
        station that came late asks for it, as QGroundControl does)."""
        self._reported_checks = self._failing_checks()
        ev.send_arming_report(self.events, self._reported_checks)
        return MAV_RESULT_ACCEPTED

    def on_offboard_setpoint(self, setpoint: ControlSetpoint, now_s: float) -> None:
        """An accepted setpoint message: proof of life in any mode."""
        was_fresh = self.offboard_signal_fresh(now_s)
        self.offboard.setpoint = setpoint
        self.offboard.received_s = now_s
        if not was_fresh and self.user_mode == modes.OFFBOARD and self.nav_mode != modes.OFFBOARD:
            self._offboard_resumed_at_s = now_s

    def on_manual_control(self, sample: StickSample, now_s: float) -> None:
        """A MANUAL_CONTROL message, for the selector to take or leave."""
        self.manual_control.take(sample, now_s)

    def on_heartbeat(self, is_gcs: bool, now_s: float) -> None:
        """GCS and onboard-controller heartbeats are tracked apart, as in PX4."""
        if not is_gcs:
            self.onboard_heartbeat_s = now_s
            return
        self.gcs_heartbeat_s = now_s
        if self.datalink_lost:
            self.datalink_lost = False
            self._announce(MAV_SEVERITY_INFO, "GCS connection regained")

    # -- periodic ----------------------------------------------------------------------

    def update(self, now_s: float, landed: bool) -> None:
        self._now_s = now_s
        self._track_landing(now_s, landed)
        self._check_offboard(now_s)
        self._check_manual_control(now_s)
        self._check_datalink(now_s)
        self._check_auto_disarm(now_s)
        self.events.update(now_s)
        if now_s - self._checked_s >= COMMANDER_MONITORING_INTERVAL_S:
            self._checked_s = now_s
            checks = self._failing_checks()
            if checks != self._reported_checks:
                self._reported_checks = checks
                ev.send_arming_report(self.events, checks)

    def _track_landing(self, now_s: float, landed: bool) -> None:
        if not landed and self.armed:
            self.took_off_since_arming = True
        if landed != self.landed and self.armed:
            self._announce(MAV_SEVERITY_INFO, "Landing detected" if landed else "Takeoff detected")
            ev.send_flight_change(self.events, landed)
        if landed and not self.landed:
            self._landed_since_s = now_s
        elif not landed:
            self._landed_since_s = None
        self.landed = landed

    def _check_auto_disarm(self, now_s: float) -> None:
        if not self.armed or not self.landed or self._landed_since_s is None:
            return
        if self.took_off_since_arming:
            timeout = self._params.get("COM_DISARM_LAND")
            cause = ev.ARM_REASON_AUTO_DISARM_LAND
        else:
            timeout = self._params.get("COM_DISARM_PRFLT")
            cause = ev.ARM_REASON_AUTO_DISARM_PREFLIGHT
        if timeout > 0 and now_s - self._landed_since_s >= timeout:
            self._disarm(cause)

    # -- internals ---------------------------------------------------------------------

    def can_arm(self) -> bool:
        """PX4's canArm for the mode flown now (its can_arm_mode_flags bit, the pre-arm bit
        of SYS_STATUS)."""
        return not (
            not self.ready
            or (self.nav_mode == modes.OFFBOARD and not self.offboard_signal_fresh())
            or (self.nav_mode in MANUAL_CONTROL_MODES and self.manual_control_lost())
            or (self.nav_mode == modes.AUTO_MISSION
                and not self._mode_available[modes.AUTO_MISSION])
            or self.nav_mode in _MODES_PREVENTING_ARMING
        )

    def _failing_checks(self) -> tuple[ev.ArmingCheck, ...]:
        """The arming checks failing now, in the order PX4's report lists them."""
        failing = (
            (not self.ready, ev.NO_LOCAL_POSITION),
            (not self.ready, ev.NO_GLOBAL_POSITION),
            (self.manual_control_lost(), self._no_manual_control_check()),
            (self.nav_mode in _MODES_PREVENTING_ARMING, ev.MODE_NOT_SUITABLE),
            (self.gcs_heartbeat_s is None or self.datalink_lost, ev.NO_DATALINK),
            (not self.offboard_signal_fresh(), ev.OFFBOARD_SIGNAL),
            (not self._mode_available[modes.AUTO_MISSION], ev.NO_MISSION),
        )
        return tuple(check for fails, check in failing if fails)

    def _no_manual_control_check(self) -> ev.ArmingCheck:
        disabled = int(self._params.get("COM_RC_IN_MODE")) == RcInMode.STICK_INPUT_DISABLED
        return ev.NO_MANUAL_CONTROL_DISABLED if disabled else ev.NO_MANUAL_CONTROL

    def _disarm(self, cause: int) -> None:
        self.armed = False
        self.took_off_since_arming = False
        self._landed_since_s = None
        # UserModeIntention::onDisarm: back to the last mode the user chose that does not
        # keep the vehicle from arming (after RTL or Land: Hold, or what came before)
        self.user_mode = self._mode_after_disarming
        self._set_nav_mode(self.user_mode)
        self._clear_failsafe()
        self._announce(MAV_SEVERITY_INFO, f"Disarmed by {ev.arm_reason_text(cause)}")
        ev.send_armed(self.events, False, cause)
        self._arm_listeners_notify()

    def _set_user_mode(self, mode: Px4Mode) -> None:
        self.user_mode = mode
        if mode not in _MODES_PREVENTING_ARMING or mode == modes.TERMINATION:
            self._mode_after_disarming = mode

    def _print_reject_mode(self, mode: Px4Mode) -> None:
        """Commander::printRejectMode: the text and its event at most once a second."""
        if self._now_s - self._mode_rejected_s <= MODE_REJECT_PRINT_INTERVAL_S:
            return
        self._mode_rejected_s = self._now_s
        self._announce(MAV_SEVERITY_CRITICAL,
                       f"Switching to {ev.mode_text(mode)} is currently not available")
        ev.send_mode_not_available(self.events, mode)

    def _set_nav_mode(self, mode: Px4Mode) -> None:
        if mode != self.nav_mode:
            self.mode_changes += 1
        self.nav_mode = mode

    def on_arming_change(self, listener: Callable[[bool], None]) -> None:
        self._arm_listeners.append(listener)

    def _arm_listeners_notify(self) -> None:
        for listener in self._arm_listeners:
            listener(self.armed)
