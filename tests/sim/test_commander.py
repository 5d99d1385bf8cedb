"""Commander timing rules: offboard availability and loss, auto-disarm, home, boot."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.flight.failsafe_actions import ObLossAction
from sim.lib import modes
from tests.sim.conftest import Harness, HarnessFactory

POSITION_AND_YAW = 0b0000_1011_1111_1000
SET_MODE = mavlink.MAV_CMD_DO_SET_MODE
ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM


def stream(h: Harness, seconds: float, rate_hz: float = 20.0, down_m: float = -3.0) -> None:
    for _ in range(round(seconds * rate_hz)):
        h.local_ned(POSITION_AND_YAW, position=(0.0, 0.0, down_m))
        h.run(1.0 / rate_hz)


def fly_offboard(h: Harness) -> None:
    stream(h, 0.3)
    h.set_mode(modes.OFFBOARD)
    h.arm()
    stream(h, 3.0)
    assert h.vehicle.mode_name == "OFFBOARD"


def offboard_ack_after_one_setpoint(h: Harness, setpoint_age_s: float) -> int:
    """Armed, one setpoint sent setpoint_age_s ago: the result of asking for OFFBOARD."""
    h.arm()
    h.local_ned(POSITION_AND_YAW, position=(0, 0, -2))
    h.run(setpoint_age_s)
    h.set_mode(modes.OFFBOARD)
    return h.last_ack(SET_MODE)


def test_one_setpoint_makes_offboard_available(harness: Harness) -> None:
    # a setpoint 0.5 s old still counts
    assert offboard_ack_after_one_setpoint(harness, 0.5) == mavlink.MAV_RESULT_ACCEPTED


def test_offboard_refused_when_setpoints_older_than_loss_timeout(harness: Harness) -> None:
    result = offboard_ack_after_one_setpoint(harness, 1.5)
    assert result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED


def test_loss_timeout_parameter_takes_effect_at_once(harness: Harness) -> None:
    harness.vehicle.params.set("COM_OF_LOSS_T", 3.0)
    assert offboard_ack_after_one_setpoint(harness, 1.5) == mavlink.MAV_RESULT_ACCEPTED


def test_stream_then_arm_in_offboard_works(harness: Harness) -> None:
    fly_offboard(harness)
    assert harness.vehicle.truth.position_ned_m[2] == pytest.approx(-3.0, abs=0.3)


def test_stream_loss_switches_to_position_after_about_1_2_s_keeping_user_mode(
    harness: Harness,
) -> None:
    fly_offboard(harness)
    last_setpoint_s = harness.vehicle.now_s
    took = harness.run_until(lambda: harness.vehicle.mode_name != "OFFBOARD", 3.0)
    assert 1.1 <= took <= 1.3, took
    assert harness.vehicle.mode_name == "POSCTL"
    assert harness.vehicle.commander.user_mode == modes.OFFBOARD
    assert harness.vehicle.now_s - last_setpoint_s == pytest.approx(took)
    harness.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_CURRENT_MODE)
    current = harness.api.of_type("CURRENT_MODE")[-1]
    assert current.custom_mode == modes.POSCTL.custom_mode
    assert current.intended_custom_mode == modes.OFFBOARD.custom_mode
    assert harness.api.of_type("HEARTBEAT")[-1].system_status in (
        mavlink.MAV_STATE_ACTIVE, mavlink.MAV_STATE_CRITICAL)


def test_position_fallback_without_rc_descends_slowly(harness: Harness) -> None:
    fly_offboard(harness)
    harness.run_until(lambda: harness.vehicle.mode_name == "POSCTL", 3.0)
    harness.run(1.0)
    vz = harness.vehicle.truth.velocity_ned_m_s[2]
    assert vz == pytest.approx(0.8, abs=0.1)
    harness.run(1.0)
    hb = [m for m in harness.api.of_type("HEARTBEAT")][-1]
    assert hb.system_status == mavlink.MAV_STATE_CRITICAL


@pytest.mark.parametrize(
    ("action", "mode_name"),
    [(ObLossAction.ALTITUDE, "ALTCTL"), (ObLossAction.RETURN, "AUTO_RTL"),
     (ObLossAction.LAND, "AUTO_LAND"), (ObLossAction.HOLD, "AUTO_LOITER")],
)
def test_loss_action_follows_com_obl_rc_act(harness: Harness, action: int,
                                            mode_name: str) -> None:
    harness.vehicle.params.set("COM_OBL_RC_ACT", action)
    fly_offboard(harness)
    harness.run_until(lambda: harness.vehicle.mode_name != "OFFBOARD", 3.0)
    assert harness.vehicle.mode_name == mode_name


def test_loss_action_disarm(harness: Harness) -> None:
    harness.vehicle.params.set("COM_OBL_RC_ACT", ObLossAction.DISARM)
    fly_offboard(harness)
    harness.run_until(lambda: not harness.vehicle.armed, 3.0)


def test_stream_resume_returns_to_offboard_at_the_next_check(harness: Harness) -> None:
    fly_offboard(harness)
    harness.run_until(lambda: harness.vehicle.mode_name == "POSCTL", 3.0)
    harness.local_ned(POSITION_AND_YAW, position=(0, 0, -3))
    took = harness.run_until(lambda: harness.vehicle.mode_name == "OFFBOARD", 1.0)
    # PX4 v1.16 SITL: 0.02-0.1 s after the first new setpoint (bench/parity_timing.py)
    assert 0.005 <= took <= 0.1
    assert not harness.vehicle.commander.failsafe


def test_no_return_to_offboard_when_user_chose_another_mode(harness: Harness) -> None:
    fly_offboard(harness)
    harness.run_until(lambda: harness.vehicle.mode_name == "POSCTL", 3.0)
    harness.set_mode(modes.AUTO_LOITER)
    stream(harness, 1.0)
    assert harness.vehicle.mode_name == "AUTO_LOITER"


def test_auto_disarm_after_com_disarm_prflt_without_takeoff(harness: Harness) -> None:
    harness.arm()
    took = harness.run_until(lambda: not harness.vehicle.armed, 15.0)
    assert took == pytest.approx(10.0, abs=0.1)
    assert "Disarmed by auto preflight disarming" in harness.api.texts()


def test_auto_disarm_after_landing_takes_com_disarm_land(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    harness.arm()
    harness.run_until(lambda: harness.vehicle.mode_name == "AUTO_LOITER", 10.0)
    harness.command_long(mavlink.MAV_CMD_NAV_LAND)
    harness.run_until(lambda: harness.vehicle.commander.landed, 20.0)
    took = harness.run_until(lambda: not harness.vehicle.armed, 5.0)
    assert took == pytest.approx(2.0, abs=0.1)


def test_home_is_set_at_arming_and_follows_while_disarmed_on_ground(harness: Harness) -> None:
    v = harness.vehicle
    assert v.commander.home.valid
    v.model.reset([80.0, 0.0, 0.0], 0.0)  # "landed 80 m away"
    harness.run(1.5)
    assert v.commander.home.position_ned_m[0] == pytest.approx(80.0)
    v.model.reset([85.0, 0.0, 0.0], 0.0)
    harness.arm()
    assert v.commander.home.position_ned_m[0] == pytest.approx(85.0)
    assert harness.api.of_type("HOME_POSITION")[-1].x == pytest.approx(85.0)


def test_first_heartbeat_after_1_5_s_and_ready_after_3_s(make_harness: HarnessFactory) -> None:
    h = make_harness(ready=False)
    h.run_until(lambda: bool(h.api.of_type("HEARTBEAT")), 5.0)
    assert h.vehicle.now_s == pytest.approx(1.5, abs=0.01)
    assert not h.vehicle.ready
    h.run_until(lambda: h.vehicle.ready, 5.0)
    assert h.vehicle.now_s == pytest.approx(3.0, abs=0.01)


def gcs_heartbeat(h: Harness) -> None:
    h.deliver(mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, 8, 0, 0, 0, 3))


def test_datalink_loss_is_only_reported_with_nav_dll_act_disabled(harness: Harness) -> None:
    gcs_heartbeat(harness)
    harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    harness.arm()
    harness.run(11.0)
    assert "Connection to ground station lost" in harness.api.texts()
    assert "Failsafe activated" not in harness.api.texts()
    assert harness.vehicle.mode_name == "AUTO_LOITER"
    assert not harness.vehicle.commander.failsafe
    gcs_heartbeat(harness)
    assert "GCS connection regained" in harness.api.texts()


def test_datalink_loss_action_follows_nav_dll_act_after_com_dl_loss_t(harness: Harness) -> None:
    harness.vehicle.params.set("NAV_DLL_ACT", 2)
    harness.vehicle.params.set("COM_DL_LOSS_T", 3)
    gcs_heartbeat(harness)
    harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    harness.arm()
    took = harness.run_until(lambda: harness.vehicle.mode_name == "AUTO_RTL", 10.0)
    assert took == pytest.approx(3.0, abs=0.05)
    assert harness.vehicle.commander.user_mode != modes.AUTO_RTL
