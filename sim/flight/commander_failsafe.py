"""The commander's failsafes: offboard, manual control and datalink loss, after PX4's
failsafe framework (``commander/failsafe``): what triggers each, and the action it takes."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from sim.flight import commander_events as ev
from sim.flight.failsafe_actions import DllAction, ObLossAction, RclAction, failsafe_mode
from sim.flight.manual_control import ManualControlSelector, RcInMode
from sim.lib import modes
from sim.lib.events import EventLog
from sim.lib.modes import Px4Mode
from sim.lib.params import ParamReader

MAV_SEVERITY_CRITICAL = 2
MAV_SEVERITY_INFO = 6

# PX4 applies a failsafe action a moment after its trigger (observed 1.1-1.3 s after the
# last setpoint) and switches back to the user's OFFBOARD at its next check once the
# stream resumes (0.02 s after the first new setpoint on PX4 v1.16 SITL).
FAILSAFE_ACTION_DELAY_S = 0.15
OFFBOARD_RESUME_DELAY_S = 0.01

# how the commander speaks: a MAV_SEVERITY and a STATUSTEXT
Announce = Callable[[int, str], None]


class CommanderFailsafes:
    """The failsafe half of the Commander: the state it shares is the Commander's own."""

    _params: ParamReader
    _announce: Announce
    events: EventLog
    armed: bool
    nav_mode: Px4Mode
    user_mode: Px4Mode
    failsafe: bool
    gcs_heartbeat_s: float | None
    datalink_lost: bool
    manual_control: ManualControlSelector
    _manual_control_lost: bool
    _manual_control_lost_at_arming: bool
    _rc_loss_action_at_s: float | None
    _rc_lost_s: float | None
    _offboard_lost_since_s: float | None
    _offboard_resumed_at_s: float | None

    if TYPE_CHECKING:
        def offboard_signal_fresh(self, now_s: float | None = None) -> bool: ...
        def manual_control_lost(self, now_s: float | None = None) -> bool: ...
        def _set_nav_mode(self, mode: Px4Mode) -> None: ...
        def _disarm(self, cause: int) -> None: ...

    def _check_manual_control(self, now_s: float) -> None:
        """RcAndDataLinkChecks and the failsafe's manual control loss: lost after
        COM_RC_LOSS_T; armed, the NAV_RCL_ACT action after COM_FAIL_ACT_T in Hold, unless
        sticks were already missing at arming, COM_RC_IN_MODE disables them, or
        COM_RCL_EXCEPT exempts the user's mode."""
        lost = self.manual_control_lost(now_s)
        was_lost, self._manual_control_lost = self._manual_control_lost, lost
        if not lost:
            self._manual_control_lost_at_arming = False
        elif not self.armed:
            self._manual_control_lost_at_arming = True
        had_input = self.manual_control.last_valid_s > -math.inf
        if lost and not was_lost and had_input:
            ev.send_rc_lost(self.events)
        elif was_lost and not lost and had_input and self._rc_lost_s is not None:
            ev.send_rc_regained(self.events, now_s - self._rc_lost_s)
        if lost and not was_lost:
            self._rc_lost_s = self.manual_control.last_valid_s
        if lost and not was_lost and self.armed and self._rc_loss_applies():
            self._start_rc_loss_failsafe(now_s)
        due = self._rc_loss_action_at_s
        if due is not None and now_s >= due:
            self._rc_loss_action_at_s = None
            self._apply_rc_loss_action()

    def _rc_loss_applies(self) -> bool:
        if self._manual_control_lost_at_arming:
            return False
        if int(self._params.get("COM_RC_IN_MODE")) == RcInMode.STICK_INPUT_DISABLED:
            return False
        exempt = int(self._params.get("COM_RCL_EXCEPT"))
        user = self.user_mode
        return not (
            (user == modes.AUTO_MISSION and exempt & 1)
            or (user in (modes.AUTO_LOITER, modes.AUTO_TAKEOFF, modes.AUTO_VTOL_TAKEOFF)
                and exempt & 2)
            or (user == modes.OFFBOARD and exempt & 4)
        )

    def _start_rc_loss_failsafe(self, now_s: float) -> None:
        action = int(self._params.get("NAV_RCL_ACT"))
        mode = failsafe_mode(RclAction, action)
        delay_s = float(self._params.get("COM_FAIL_ACT_T"))
        self.failsafe = True
        if action in (RclAction.TERMINATE, RclAction.DISARM) or delay_s <= 0.1:
            self._apply_rc_loss_action()
            return
        # the framework holds first, so the pilot can notice, then acts
        self._announce(MAV_SEVERITY_CRITICAL,
                       f"Failsafe activated: entering Hold for {round(delay_s)} seconds")
        ev.send_failsafe_hold(self.events, self.user_mode, mode, round(delay_s))
        self._set_nav_mode(modes.AUTO_LOITER)
        self._rc_loss_action_at_s = now_s + delay_s

    def _apply_rc_loss_action(self) -> None:
        action = int(self._params.get("NAV_RCL_ACT"))
        mode = failsafe_mode(RclAction, action)
        self.failsafe = True
        if action == RclAction.DISARM:
            ev.send_failsafe(self.events, self.user_mode, None)
            self._disarm(ev.ARM_REASON_FAILSAFE)
        elif mode is not None:
            self._set_nav_mode(mode)

    def _check_datalink(self, now_s: float) -> None:
        last = self.gcs_heartbeat_s
        if self.datalink_lost or last is None:
            return
        if now_s - last <= self._params.get("COM_DL_LOSS_T"):
            return
        self.datalink_lost = True
        self._announce(MAV_SEVERITY_INFO, "Connection to ground station lost")
        action = int(self._params.get("NAV_DLL_ACT"))
        if not self.armed or action == DllAction.DISABLED:
            return
        self._announce(MAV_SEVERITY_CRITICAL, "Failsafe activated")
        self.failsafe = True
        mode = failsafe_mode(DllAction, action)
        ev.send_failsafe(self.events, self.user_mode, mode)
        if action == DllAction.DISARM:
            self._disarm(ev.ARM_REASON_FAILSAFE)
        elif mode is not None:
            self._set_nav_mode(mode)

    def _check_offboard(self, now_s: float) -> None:
        if self.user_mode != modes.OFFBOARD:
            return
        if self.offboard_signal_fresh(now_s):
            self._offboard_lost_since_s = None
            resumed = self._offboard_resumed_at_s
            if resumed is not None and now_s - resumed >= OFFBOARD_RESUME_DELAY_S:
                self._offboard_resumed_at_s = None
                if self.nav_mode != modes.OFFBOARD:
                    self._set_nav_mode(modes.OFFBOARD)
                    self._clear_failsafe()
            return
        if not self.armed or self.nav_mode != modes.OFFBOARD:
            return
        if self._offboard_lost_since_s is None:
            self._offboard_lost_since_s = now_s
        if now_s - self._offboard_lost_since_s >= FAILSAFE_ACTION_DELAY_S:
            self._offboard_lost_since_s = None
            self._apply_offboard_loss_action()

    def _apply_offboard_loss_action(self) -> None:
        action = int(self._params.get("COM_OBL_RC_ACT"))
        self._announce(MAV_SEVERITY_CRITICAL, "Failsafe activated")
        self.failsafe = True
        mode = failsafe_mode(ObLossAction, action)
        if action == ObLossAction.DISARM:
            ev.send_failsafe(self.events, self.user_mode, None)
            self._disarm(ev.ARM_REASON_FAILSAFE)
            return
        ev.send_failsafe(self.events, self.user_mode, modes.POSCTL if mode is None else mode)
        self._set_nav_mode(modes.POSCTL if mode is None else mode)

    def _clear_failsafe(self) -> None:
        self.failsafe = False
        self._offboard_lost_since_s = None
        self._rc_loss_action_at_s = None
