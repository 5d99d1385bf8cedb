"""PX4's health and arming check report, read as libevents' HealthAndArmingChecks reads it,
and the vehicle's readiness to arm made of it (or of SYS_STATUS when there is no report).

PX4's commander (HealthAndArmingChecks/Common.cpp, Report::report) sends its report whenever
the result changes, and again on MAV_CMD_RUN_PREARM_CHECKS: the summary
``commander_arming_check_summary`` (chunk, error and warning components, the mode groups
that can arm and that can run), one event per check that failed or warned (its first
argument the mode groups it concerns, its second the health component's index), and the
``commander_health_summary`` that ends it. A mode group is one navigation state
(``1 << nav_state``). A report counts once its health summary came; until then the last
complete one stands.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.snapshot import ArmingCheck, ArmingChecksState

# libevents' log levels (the low nibble of an EVENT's log_levels is the external one)
EVENT_LOG_LEVEL_NAMES = (
    "EMERGENCY", "ALERT", "CRITICAL", "ERROR", "WARNING", "NOTICE", "INFO", "DEBUG",
    "PROTOCOL", "DISABLED",
)  # fmt: skip
LOG_LEVEL_ERROR = 3
ARMING_CHECK_SUMMARY = "commander_arming_check_summary"
HEALTH_SUMMARY = "commander_health_summary"
# PX4's navigation states by the API's mode names: a check's "modes" argument and the
# summary's can_arm have bit 1 << nav_state set per mode (navigation_mode_group_t: group
# == mode)
NAV_STATES = {
    "MANUAL": 0, "ALTCTL": 1, "POSCTL": 2, "MISSION": 3, "HOLD": 4, "RTL": 5, "ACRO": 10,
    "TERMINATION": 13, "OFFBOARD": 14, "STABILIZED": 15, "TAKEOFF": 17, "LAND": 18,
    "FOLLOW_TARGET": 19, "PRECLAND": 20, "POSCTL_ORBIT": 21, "VTOL_TAKEOFF": 22,
}  # fmt: skip
_MODE_NAMES = {nav_state: name for name, nav_state in NAV_STATES.items()}
# mode_requirements.cpp: mode_req_prevent_arming, by the names PX4 reports them under
# (DESCEND reports as LAND). PX4 checks it for the mode flown only, so its report's can_arm
# keeps these modes' bits while another mode is flown, though it would refuse to arm in them.
MODES_PREVENTING_ARMING = frozenset({"RTL", "LAND", "PRECLAND", "FOLLOW_TARGET", "POSCTL_ORBIT"})
# with TERMINATION, which PX4 never leaves: the modes its check names
_NOT_SUITABLE_MODES = tuple(
    sorted(MODES_PREVENTING_ARMING | {"TERMINATION"}, key=lambda m: NAV_STATES[m])
)
# PX4's words for it, and its log level: v1.16 SITL reports it as an INFO that names every
# one of those modes, and only while one of them is flown
NOT_SUITABLE_FOR_ARMING = "Mode not suitable for arming"
_NOT_SUITABLE_LEVEL = "INFO"


def log_level_name(level: int) -> str:
    return EVENT_LOG_LEVEL_NAMES[level] if 0 <= level < len(EVENT_LOG_LEVEL_NAMES) else str(level)


def mode_names(mode_groups: int) -> tuple[str, ...]:
    """The API's names of the modes whose bits are set (PX4's external modes have none)."""
    return tuple(name for bit, name in sorted(_MODE_NAMES.items()) if mode_groups >> bit & 1)


@dataclass(frozen=True)
class ReportedCheck:
    text: str
    log_level: int
    mode_groups: int
    component: str | None
    group: str  # "arming_check" or "health"

    def concerns(self, nav_state: int | None) -> bool:
        return nav_state is None or bool(self.mode_groups >> nav_state & 1)

    def shown(self) -> ArmingCheck:
        return ArmingCheck(
            self.text, log_level_name(self.log_level), mode_names(self.mode_groups),
            self.component, "health" if self.group == "health" else "arming_check",
        )  # fmt: skip


@dataclass(frozen=True)
class CheckReport:
    can_arm: int  # mode groups that could arm now
    can_run: int  # mode groups that could run now (armed)
    checks: tuple[ReportedCheck, ...]


class CheckReportReader:
    """Assembles the events of one report; ``report`` is the last complete one."""

    def __init__(self, health_components: dict[int, str] | None = None) -> None:
        # health_component_t: index (bit number) -> PX4's description ("Global position
        # estimate"), from the vehicle's events metadata
        self.health_components = health_components or {}
        self.report: CheckReport | None = None
        self._pending: tuple[int, int, list[ReportedCheck]] | None = None

    def take(self, name: str, group: str, text: str, level: int, arguments: list[object]) -> bool:
        """One event of the arming_check or health group; True when it completed a report."""
        if name == ARMING_CHECK_SUMMARY:
            can_arm, can_run = (_int(arguments, i) for i in (3, 4))
            self._pending = (can_arm, can_run if len(arguments) > 4 else can_arm, [])
            return False
        if self._pending is None:
            return False  # a report whose summary we missed: wait for the next one
        if name == HEALTH_SUMMARY:
            can_arm, can_run, checks = self._pending
            self._pending = None
            self.report = CheckReport(can_arm, can_run, tuple(checks))
            return True
        component = self.health_components.get(_int(arguments, 1))
        self._pending[2].append(ReportedCheck(text, level, _int(arguments, 0), component, group))
        return False

    def forget(self) -> None:
        self.report = None
        self._pending = None

    def failing(self, nav_state: int | None) -> list[str]:
        """The texts of the errors that concern a mode (any mode for None)."""
        if self.report is None:
            return []
        return [
            c.text
            for c in self.report.checks
            if c.log_level <= LOG_LEVEL_ERROR and c.concerns(nav_state)
        ]


def _int(arguments: list[object], index: int) -> int:
    value = arguments[index] if index < len(arguments) else 0
    return value if isinstance(value, int) else 0


def readiness(
    report: CheckReport | None,
    mode: str,
    ready_to_arm: bool | None,
    sensors_unhealthy: tuple[str, ...] | None,
    *,
    arm_switches_to: str | None = None,
    waiting_for: tuple[str, ...] = (),
) -> ArmingChecksState:
    """Ready to arm in the mode flown, and why not: from PX4's check report when there is
    one, else from SYS_STATUS (its pre-arm bit, and the sensors it reports unhealthy).

    ``arm_switches_to`` is the mode the server's arm switches to first from ``mode`` (None:
    it arms in ``mode``); ``waiting_for`` what a takeoff or an offboard start still needs.
    Both make the verdict: "ready" only when PX4 would arm and nothing is awaited;
    "arm_switches_mode" when PX4 refuses ``mode`` but would arm in the mode switched to."""
    if report is None:
        reasons = tuple(
            ArmingCheck(f"{_sensor_label(name)}: not healthy", "ERROR", (), None, "health")
            for name in sensors_unhealthy or ()
        )
        verdict = _verdict(ready_to_arm, False, waiting_for)
        return ArmingChecksState(
            ready_to_arm, mode, "sys_status", (), reasons, (), verdict, None, waiting_for
        )
    nav_state = NAV_STATES.get(mode)
    ready = ready_to_arm if nav_state is None else bool(report.can_arm >> nav_state & 1)
    # PX4 would refuse these whatever its report's bits say (it checks the flown mode only)
    can_arm = tuple(m for m in mode_names(report.can_arm) if m not in _NOT_SUITABLE_MODES)
    switch_helps = arm_switches_to is not None and arm_switches_to in can_arm
    # the errors first: they are what keeps the vehicle on the ground
    ordered = sorted(report.checks, key=lambda c: c.log_level)
    others = [c.shown() for c in ordered if nav_state is None or not c.concerns(nav_state)]
    told = {m for c in report.checks if c.text == NOT_SUITABLE_FOR_ARMING
            for m in mode_names(c.mode_groups)}  # fmt: skip
    refused = tuple(m for m in _NOT_SUITABLE_MODES if m not in told)
    current = [c.shown() for c in ordered if nav_state is not None and c.concerns(nav_state)]
    if refused:  # as PX4 would say it once in one of them
        not_suitable = ArmingCheck(
            NOT_SUITABLE_FOR_ARMING, _NOT_SUITABLE_LEVEL, refused, None, "arming_check"
        )
        if mode in refused:  # a report from before the switch to a mode PX4 never arms in
            ready = False
            current.append(not_suitable)
        else:
            others.append(not_suitable)
    return ArmingChecksState(
        ready,
        mode,
        "events",
        can_arm,
        tuple(current),
        tuple(others),
        _verdict(ready, switch_helps, waiting_for),
        arm_switches_to if not ready and switch_helps else None,
        waiting_for,
    )


def _verdict(
    ready: bool | None, switch_helps: bool, waiting_for: tuple[str, ...]
) -> Literal["ready", "arm_switches_mode", "not_ready"] | None:
    if ready is None:
        return None
    if waiting_for:
        return "not_ready"
    if ready:
        return "ready"
    return "arm_switches_mode" if switch_helps else "not_ready"


def _sensor_label(name: str) -> str:
    """MAVLink's description of a MAV_SYS_STATUS_SENSOR bit ("0x20 GPS" -> "GPS")."""
    for entry in mavlink.enums["MAV_SYS_STATUS_SENSOR"].values():
        if entry.name == f"MAV_SYS_STATUS_{name}" and entry.description:
            description = str(entry.description)
            words = description.split(" ", 1)
            return words[1] if words[0].startswith("0x") and len(words) > 1 else description
    return name
