"""Ready to fly: PX4's arming-check report (summary, checks, health summary) read into the
state's arming_checks, judged for the mode flown; SYS_STATUS's bits when no report came."""

from __future__ import annotations

from pathlib import Path

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.arming_checks import NAV_STATES, CheckReport, ReportedCheck, readiness
from server.link.core.state import ArmingChecksState
from tests.link.conftest import ScriptedSession
from tests.link.test_px4_events import (
    ALL_MODE_GROUPS,
    CHECK_SUMMARY,
    ERROR,
    HEALTH_GLOBAL_POSITION,
    HEALTH_SYSTEM,
    INFO,
    NO_GCS,
    NO_GLOBAL_POSITION,
    OFFBOARD_MODE_GROUP,
    OFFBOARD_SIGNAL,
    PROTOCOL,
    _loaded,
)
from tests.link.test_state_health import _sys_status
from tests.waiting import wait_for

POSCTL, HOLD, OFFBOARD = 0x30000, 0x3040000, 0x60000
NO_POSITION = "Navigation error: No valid global position estimate"
NO_SIGNAL = "No offboard signal"
NO_LINK = "No connection to the ground control station"
NOT_SUITABLE = "Mode not suitable for arming"
# as PX4 v1.16 SITL names them in that check (by nav_state), at INFO
PREVENTING = ("RTL", "TERMINATION", "LAND", "FOLLOW_TARGET", "PRECLAND", "POSCTL_ORBIT")


def _checks(scripted: ScriptedSession) -> ArmingChecksState:
    checks = scripted.vehicle.snapshot().arming_checks
    assert checks is not None
    return checks


async def test_not_ready_with_px4s_reasons_then_ready_once_the_report_clears(
    scripted: ScriptedSession, tmp_path: Path
) -> None:
    px4 = await _loaded(scripted, tmp_path)
    scripted.peer.report_mode(HOLD, HOLD)
    # just after boot: no global position (every mode), no offboard signal (OFFBOARD), and
    # a notice that blocks nothing
    px4.report(0, [
        (NO_GLOBAL_POSITION, ERROR, ALL_MODE_GROUPS, HEALTH_GLOBAL_POSITION),
        (NO_GCS, INFO, ALL_MODE_GROUPS, 0),
        (OFFBOARD_SIGNAL, ERROR, OFFBOARD_MODE_GROUP, HEALTH_SYSTEM),
    ])  # fmt: skip
    await wait_for(lambda: _checks(scripted).source == "events", 2.0, "the report")
    checks = _checks(scripted)
    assert (checks.ready, checks.mode, checks.can_arm_modes) == (False, "HOLD", ())
    # the errors first, each in PX4's words with its component and modes
    assert [(c.text, c.severity) for c in checks.reasons] == [
        (NO_POSITION, "ERROR"), (NO_LINK, "INFO")]  # fmt: skip
    assert checks.reasons[0].component == "Global position estimate"
    assert "HOLD" in checks.reasons[0].modes
    assert "OFFBOARD" in checks.reasons[0].modes
    # and, in PX4's words, the modes it refuses to arm in whatever its report's bits say
    assert [(c.text, c.modes, c.component) for c in checks.other_reasons] == [
        (NO_SIGNAL, ("OFFBOARD",), "System"), (NOT_SUITABLE, PREVENTING, None)]  # fmt: skip

    # the position came: every mode but OFFBOARD can arm
    px4.report(ALL_MODE_GROUPS & ~OFFBOARD_MODE_GROUP, [
        (OFFBOARD_SIGNAL, ERROR, OFFBOARD_MODE_GROUP, HEALTH_SYSTEM)])  # fmt: skip
    await wait_for(lambda: _checks(scripted).ready, 2.0, "ready in HOLD")
    checks = _checks(scripted)
    assert checks.reasons == ()
    assert "OFFBOARD" not in checks.can_arm_modes
    assert "POSCTL" in checks.can_arm_modes
    # the same report judged for another mode flown
    scripted.peer.report_mode(OFFBOARD, OFFBOARD)
    await wait_for(lambda: _checks(scripted).mode == "OFFBOARD", 2.0, "OFFBOARD")
    checks = _checks(scripted)
    assert checks.ready is False
    assert [c.text for c in checks.reasons] == [NO_SIGNAL]


async def test_a_report_counts_only_once_its_health_summary_came(
    scripted: ScriptedSession, tmp_path: Path
) -> None:
    px4 = await _loaded(scripted, tmp_path)
    scripted.peer.report_mode(POSCTL, POSCTL)
    px4.report(ALL_MODE_GROUPS, [])
    await wait_for(lambda: _checks(scripted).ready, 2.0, "ready")
    # a report cut short (its health summary lost) leaves the last whole one standing
    px4.event(CHECK_SUMMARY, PROTOCOL, bytes(17))
    await scripted.vehicle_heard_all()
    assert _checks(scripted).ready is True


async def test_without_events_the_pre_arm_bit_and_unhealthy_sensors_of_sys_status(
    scripted: ScriptedSession,
) -> None:
    assert _checks(scripted).ready is None  # nothing told yet
    gps, prearm = mavlink.MAV_SYS_STATUS_SENSOR_GPS, mavlink.MAV_SYS_STATUS_PREARM_CHECK
    scripted.peer.send(_sys_status(gps | prearm, 0))
    await wait_for(lambda: _checks(scripted).ready is False, 2.0, "not ready")
    checks = _checks(scripted)
    assert checks.source == "sys_status"
    assert [(c.text, c.kind) for c in checks.reasons] == [("GPS: not healthy", "health")]
    scripted.peer.send(_sys_status(gps | prearm, gps | prearm))
    await wait_for(lambda: _checks(scripted).ready is True, 2.0, "ready")
    assert _checks(scripted).reasons == ()


# -- the verdict: ready, ready once Arm has switched mode, not ready -----------------------

_EVERY_MODE = sum(1 << n for n in NAV_STATES.values())
_LOG_ERROR = 3


def _report(can_arm_except: tuple[str, ...], *failing: tuple[str, str]) -> CheckReport:
    """PX4's report: every mode can arm but ``can_arm_except``; ``failing`` (text, mode)."""
    can_arm = _EVERY_MODE & ~sum(1 << NAV_STATES[m] for m in can_arm_except)
    checks = tuple(ReportedCheck(text, _LOG_ERROR, 1 << NAV_STATES[mode], None, "arming_check")
                   for text, mode in failing)  # fmt: skip
    return CheckReport(can_arm, can_arm, checks)


def test_ready_only_with_home_and_a_position() -> None:
    report = _report(("OFFBOARD",), (NO_SIGNAL, "OFFBOARD"))
    assert readiness(report, "HOLD", True, None).verdict == "ready"
    waiting = readiness(report, "HOLD", True, None, waiting_for=("home position",))
    assert (waiting.ready, waiting.verdict, waiting.waiting_for) == (
        True, "not_ready", ("home position",))  # fmt: skip


def test_after_a_landing_in_land_or_offboard_arm_switches_to_hold_first() -> None:
    # PX4 after an RTL ended disarmed: in LAND, only the mode's own check fails
    landed = readiness(
        _report(("LAND", "OFFBOARD"), (NOT_SUITABLE, "LAND"), (NO_SIGNAL, "OFFBOARD")),
        "LAND", False, None, arm_switches_to="HOLD",
    )  # fmt: skip
    assert (landed.ready, landed.verdict, landed.arm_switches_to) == (
        False, "arm_switches_mode", "HOLD")  # fmt: skip
    assert [c.text for c in landed.reasons] == [NOT_SUITABLE]
    # PX4's own check for LAND is not told twice
    assert [c.modes for c in landed.other_reasons if c.text == NOT_SUITABLE] == [
        tuple(m for m in PREVENTING if m != "LAND")]  # fmt: skip
    offboard = readiness(_report(("OFFBOARD",), (NO_SIGNAL, "OFFBOARD")), "OFFBOARD", False,
                         None, arm_switches_to="HOLD")  # fmt: skip
    assert offboard.verdict == "arm_switches_mode"


def test_not_ready_when_hold_would_fail_too_or_arm_does_not_switch() -> None:
    no_position = _report(tuple(NAV_STATES), ("No valid global position estimate", "HOLD"))
    assert readiness(no_position, "LAND", False, None, arm_switches_to="HOLD").verdict == (
        "not_ready")  # fmt: skip
    mission = _report(("MISSION",), ("No valid mission", "MISSION"))
    checks = readiness(mission, "MISSION", False, None, arm_switches_to=None)
    assert (checks.verdict, checks.arm_switches_to) == ("not_ready", None)


def test_modes_px4_refuses_to_arm_in_are_not_listed_as_able_to_arm() -> None:
    # flying HOLD, PX4's report keeps LAND's and RTL's bits: it checks the flown mode only
    checks = readiness(_report(()), "HOLD", True, None)
    assert not set(PREVENTING) & set(checks.can_arm_modes)
    assert {"HOLD", "POSCTL", "MISSION", "OFFBOARD"} <= set(checks.can_arm_modes)
    refused = [c for c in checks.other_reasons if c.text == NOT_SUITABLE]
    assert [(c.modes, c.severity) for c in refused] == [(PREVENTING, "INFO")]
