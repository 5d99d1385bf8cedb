"""The events PX4's commander sends, with its arguments and log levels (PX4 v1.16).

Arming checks are reported as PX4's health and arming check report does it: when the set of
failing checks changes, a summary (commander_arming_check_summary), one event per failing
check (navigation modes it blocks, health component index) and a health summary. A refused
arm then only says "Arming denied: Resolve system health failures first"; the reason is the
check reported before (what QGroundControl shows).
"""

from __future__ import annotations

from dataclasses import dataclass

from sim.lib import modes
from sim.lib.events import (
    LOG_CRITICAL,
    LOG_ERROR,
    LOG_INFO,
    LOG_PROTOCOL,
    LOG_WARNING,
    EventLog,
    log_levels,
)
from sim.lib.modes import Px4Mode

# navigation_mode_group_t bits (one per vehicle_status nav_state)
NAV_GROUP_MISSION = 1 << 3
# a multicopter's mode requirements (ModeUtil/mode_requirements.cpp), as PX4 v1.16 SITL's
# SIH quad names them after boot: a local position for posctl, mission, loiter, rtl,
# takeoff, land, follow target, precland, orbit, vtol takeoff; a global one for mission,
# loiter, rtl
NAV_GROUP_LOCAL_POSITION = sum(1 << bit for bit in (2, 3, 4, 5, 17, 18, 19, 20, 21, 22))
NAV_GROUP_GLOBAL_POSITION = sum(1 << bit for bit in (3, 4, 5))
NAV_GROUP_OFFBOARD = 1 << 14
# mode_req_manual_control: manual, altctl, posctl, acro, stab
NAV_GROUP_MANUAL_CONTROL = sum(1 << bit for bit in (0, 1, 2, 10, 15))
NAV_GROUP_ALL = 0xFFFFFFFF
# the modes the simulated vehicle flies: manual, altctl, posctl, mission, loiter, rtl, acro,
# offboard, stab, takeoff, land
NAV_GROUPS_SUPPORTED = sum(1 << bit for bit in (0, 1, 2, 3, 4, 5, 10, 14, 15, 17, 18))
# health_component_t bits as indices (the uint8 argument of a check event)
HEALTH_REMOTE_CONTROL = 7
HEALTH_COMMUNICATION_LINKS = 12
HEALTH_LOCAL_POSITION = 17
HEALTH_GLOBAL_POSITION = 24
HEALTH_SYSTEM = 20
# health components PX4's SIH quad reports present
HEALTH_PRESENT_SIH = 0x38020C0A

# arm_disarm_reason_t
ARM_REASON_COMMAND_EXTERNAL = 4
ARM_REASON_AUTO_DISARM_LAND = 6
ARM_REASON_AUTO_DISARM_PREFLIGHT = 7
ARM_REASON_FAILSAFE = 14

# failsafe_action_t by the mode a failsafe flies
_FAILSAFE_ACTIONS = {
    modes.POSCTL: 2, modes.ALTCTL: 3, modes.STABILIZED: 4, modes.AUTO_LOITER: 5,
    modes.AUTO_RTL: 6, modes.AUTO_LAND: 7, modes.TERMINATION: 10,
}
FAILSAFE_ACTION_POSCTRL = 2
FAILSAFE_ACTION_DISARM = 9

# navigation_mode_t (vehicle_status nav_state) of each mode
_NAVIGATION_MODES = {
    modes.MANUAL: 0, modes.ALTCTL: 1, modes.POSCTL: 2, modes.AUTO_MISSION: 3,
    modes.AUTO_LOITER: 4, modes.AUTO_RTL: 5, modes.ACRO: 6, modes.OFFBOARD: 7,
    modes.STABILIZED: 8, modes.AUTO_TAKEOFF: 10, modes.AUTO_LAND: 11,
    modes.AUTO_FOLLOW_TARGET: 12, modes.AUTO_PRECLAND: 13, modes.ORBIT: 14,
    modes.AUTO_VTOL_TAKEOFF: 15,
}
NAVIGATION_MODE_UNKNOWN = 255
# lib/modes/ui.hpp nav_state_names: how PX4's STATUSTEXT names a mode
_NAV_STATE_NAMES = {
    modes.MANUAL: "Manual", modes.ALTCTL: "Altitude", modes.POSCTL: "Position",
    modes.AUTO_MISSION: "Mission", modes.AUTO_LOITER: "Hold", modes.AUTO_RTL: "Return",
    modes.ACRO: "Acro", modes.OFFBOARD: "Offboard", modes.STABILIZED: "Stabilized",
    modes.AUTO_TAKEOFF: "Takeoff", modes.AUTO_LAND: "Land",
    modes.AUTO_FOLLOW_TARGET: "Follow Target", modes.AUTO_PRECLAND: "Precision Landing",
    modes.ORBIT: "Orbit", modes.AUTO_VTOL_TAKEOFF: "VTOL Takeoff",
    modes.TERMINATION: "Termination",
}
# Commander.cpp arm_disarm_reason_str, for "Armed by ..." / "Disarmed by ..."
_ARM_REASON_TEXTS = {
    ARM_REASON_COMMAND_EXTERNAL: "external command",
    ARM_REASON_AUTO_DISARM_LAND: "landing",
    ARM_REASON_AUTO_DISARM_PREFLIGHT: "auto preflight disarming",
    ARM_REASON_FAILSAFE: "failsafe",
}


@dataclass(frozen=True)
class ArmingCheck:
    """One failing check: its event, the modes it names, its component and level, and
    whether it keeps those modes from arming (PX4 names all modes for a mere notice)."""

    name: str
    nav_groups: int
    health_index: int
    level: int
    blocks: bool = True
    blocked_groups: int | None = None  # when it blocks other modes than the event names


OFFBOARD_SIGNAL = ArmingCheck("check_modes_offboard_signal", NAV_GROUP_OFFBOARD,
                              HEALTH_SYSTEM, LOG_ERROR)
NO_MISSION = ArmingCheck("check_modes_mission", NAV_GROUP_MISSION, HEALTH_SYSTEM, LOG_INFO)
# until the estimator has a position (the first seconds after boot)
NO_LOCAL_POSITION = ArmingCheck("check_modes_local_pos", NAV_GROUP_LOCAL_POSITION,
                                HEALTH_LOCAL_POSITION, LOG_ERROR)
NO_GLOBAL_POSITION = ArmingCheck("check_modes_global_pos", NAV_GROUP_GLOBAL_POSITION,
                                 HEALTH_GLOBAL_POSITION, LOG_ERROR)
# without a GCS link required (NAV_DLL_ACT 0) only a notice
NO_DATALINK = ArmingCheck("check_rc_dl_no_dllink", NAV_GROUP_ALL, HEALTH_COMMUNICATION_LINKS,
                          LOG_INFO, blocks=False)
# modeCheck: without stick input the manual modes cannot arm or run; a warning that names
# no mode (reported as every mode), unless COM_RC_IN_MODE disabled the sticks (then an
# error naming the modes)
NO_MANUAL_CONTROL = ArmingCheck("check_modes_manual_control", 0, HEALTH_REMOTE_CONTROL,
                                LOG_WARNING, blocked_groups=NAV_GROUP_MANUAL_CONTROL)
NO_MANUAL_CONTROL_DISABLED = ArmingCheck("check_modes_manual_control", NAV_GROUP_MANUAL_CONTROL,
                                         HEALTH_REMOTE_CONTROL, LOG_ERROR)
# modeCheck checkArmingRequirement: the modes of mode_req_prevent_arming (RTL 5, DESCEND 12,
# TERMINATION 13, LAND 18, FOLLOW_TARGET 19, PRECLAND 20, ORBIT 21), reported while in one
NAV_GROUP_PREVENT_ARMING = sum(1 << bit for bit in (5, 12, 13, 18, 19, 20, 21))
MODE_NOT_SUITABLE = ArmingCheck("check_modes_cannot_takeoff", NAV_GROUP_PREVENT_ARMING,
                                HEALTH_SYSTEM, LOG_INFO)
# failsafe_cause_t
FAILSAFE_CAUSE_MANUAL_CONTROL_LOSS = 1


def send_arming_report(events: EventLog, checks: tuple[ArmingCheck, ...]) -> None:
    error = warning = 0
    blocked = 0
    for check in checks:
        if check.level <= LOG_ERROR:
            error |= 1 << check.health_index
        elif check.level == LOG_WARNING:
            warning |= 1 << check.health_index
        if check.blocks:
            blocked |= check.nav_groups if check.blocked_groups is None else check.blocked_groups
    can_arm = NAV_GROUPS_SUPPORTED & ~blocked
    events.send("commander_arming_check_summary", log_levels(LOG_PROTOCOL), 0, error, warning,
                can_arm, can_arm)
    for check in checks:
        events.send(check.name, log_levels(check.level), _reported_modes(check.nav_groups),
                    check.health_index)
    events.send("commander_health_summary", log_levels(LOG_PROTOCOL), 0, HEALTH_PRESENT_SIH,
                error, warning)


def _reported_modes(nav_groups: int) -> int:
    """Report::reportedModes: a check that requires no mode is shown in every mode."""
    return nav_groups or NAV_GROUP_ALL


def send_arm_denied(events: EventLog) -> None:
    events.send("commander_arm_denied_resolve_failures", log_levels(LOG_CRITICAL, LOG_INFO))


def send_disarm_denied(events: EventLog) -> None:
    events.send("commander_disarm_denied_not_landed", log_levels(LOG_CRITICAL, LOG_INFO))


def send_mode_not_available(events: EventLog, mode: Px4Mode) -> None:
    events.send("commander_modeswitch_not_avail", log_levels(LOG_CRITICAL, LOG_INFO),
                mode.custom_mode, _NAVIGATION_MODES.get(mode, NAVIGATION_MODE_UNKNOWN))


def send_armed(events: EventLog, armed: bool, reason: int) -> None:
    name = "commander_armed_by" if armed else "commander_disarmed_by"
    events.send(name, log_levels(LOG_INFO), reason)


def send_failsafe(events: EventLog, user_mode: Px4Mode, action_mode: Px4Mode | None) -> None:
    """commander_failsafe_enter_generic: the custom mode of the user's mode it interrupts
    (seen on PX4 v1.16: OFFBOARD for an offboard loss) and the action (None: disarm)."""
    action = (FAILSAFE_ACTION_DISARM if action_mode is None
              else _FAILSAFE_ACTIONS.get(action_mode, FAILSAFE_ACTION_POSCTRL))
    events.send("commander_failsafe_enter_generic", log_levels(LOG_CRITICAL, LOG_WARNING),
                user_mode.custom_mode, action)


def send_failsafe_hold(
    events: EventLog, user_mode: Px4Mode, action_mode: Px4Mode | None, delay_s: int
) -> None:
    """commander_failsafe_enter_hold: Hold first, the action after delay_s."""
    action = (FAILSAFE_ACTION_DISARM if action_mode is None
              else _FAILSAFE_ACTIONS.get(action_mode, FAILSAFE_ACTION_POSCTRL))
    events.send("commander_failsafe_enter_hold", log_levels(LOG_CRITICAL, LOG_WARNING),
                user_mode.custom_mode, action, delay_s, FAILSAFE_CAUSE_MANUAL_CONTROL_LOSS)


def send_rc_lost(events: EventLog) -> None:
    events.send("commander_rc_lost", log_levels(LOG_INFO))


def send_rc_regained(events: EventLog, after_s: float) -> None:
    events.send("commander_rc_regained", log_levels(LOG_INFO), after_s)


def send_command_decision(events: EventLog, name: str) -> None:
    """What the commander says when it takes a command: commander_rtl,
    commander_landing_current_pos (Info)."""
    events.send(name, log_levels(LOG_INFO))


def send_flight_change(events: EventLog, landed: bool) -> None:
    name = "commander_landing_detected" if landed else "commander_takeoff_detected"
    events.send(name, log_levels(LOG_INFO))


def mode_text(mode: Px4Mode) -> str:
    """PX4's name of a mode in STATUSTEXT ("Switching to Offboard is ...")."""
    return _NAV_STATE_NAMES.get(mode, mode.name)


def arm_reason_text(reason: int) -> str:
    return _ARM_REASON_TEXTS.get(reason, "")
