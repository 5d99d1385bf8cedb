"""Ready to fly: PX4's arming-check report (summary, checks, health summary) read into the
state's arming_checks, judged for the mode flown; SYS_STATUS's bits when no report came."""

from __future__ import annotations

from pathlib import Path

from pymavlink.dialects.v20 import development as mavlink

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
    assert [(c.text, c.modes, c.component) for c in checks.other_reasons] == [
        (NO_SIGNAL, ("OFFBOARD",), "System")]  # fmt: skip

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
