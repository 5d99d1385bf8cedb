"""COMMAND_LONG / COMMAND_INT / SET_MODE handling and their COMMAND_ACKs, as PX4 v1.16."""

from __future__ import annotations

import math
import struct

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.lib import modes
from tests.sim.conftest import GCS_COMPID, GCS_SYSID, Harness, HarnessFactory

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
FAILED = mavlink.MAV_RESULT_FAILED
ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
SET_MODE = mavlink.MAV_CMD_DO_SET_MODE
REPOSITION = mavlink.MAV_CMD_DO_REPOSITION


def test_ack_goes_to_the_sender_with_its_ids(harness: Harness) -> None:
    harness.arm()
    (ack,) = harness.api.acks(ARM)
    assert (ack.result, ack.target_system, ack.target_component) == (
        ACCEPTED, GCS_SYSID, GCS_COMPID)
    assert harness.gcs.acks() == []


def test_commands_answer_on_the_link_they_came_from(harness: Harness) -> None:
    harness.command_long(ARM, 1, link=harness.gcs)
    assert harness.gcs.acks(ARM)
    assert not harness.api.acks(ARM)


@pytest.mark.parametrize(("target_system", "target_component"), [(2, 1), (0, 1), (1, 5)])
def test_commands_for_other_targets_are_ignored(harness: Harness, target_system: int,
                                                target_component: int) -> None:
    harness.command_long(ARM, 1, target_system=target_system, target_component=target_component)
    assert harness.api.acks() == []
    assert not harness.vehicle.armed


def test_component_zero_means_any_component(harness: Harness) -> None:
    harness.command_long(ARM, 1, target_component=0)
    assert harness.last_ack(ARM) == ACCEPTED


def test_version_request_is_answered_for_target_system_zero(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE,
                         mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION, target_system=0)
    assert harness.last_ack(mavlink.MAV_CMD_REQUEST_MESSAGE) == ACCEPTED
    (version,) = harness.api.of_type("AUTOPILOT_VERSION")
    assert version.flight_sw_version >> 24 == 1
    assert (version.flight_sw_version >> 16) & 0xFF == 16


def test_unknown_command_is_unsupported(harness: Harness) -> None:
    harness.command_long(31337)
    assert harness.last_ack(31337) == UNSUPPORTED


def test_arm_with_other_param1_gets_no_ack(harness: Harness) -> None:
    harness.command_long(ARM, 0.5)
    harness.command_long(ARM, 2)
    assert harness.api.acks() == []
    assert not harness.vehicle.armed


def test_arming_twice_is_accepted_both_times(harness: Harness) -> None:
    harness.arm()
    harness.arm()
    assert [a.result for a in harness.api.acks(ARM)] == [ACCEPTED, ACCEPTED]


def test_arming_before_ready_is_refused_with_reason(make_harness: HarnessFactory) -> None:
    h = make_harness(ready=False)
    h.run(2.0)
    h.arm()
    assert h.last_ack(ARM) == TEMPORARILY_REJECTED
    assert "Arming denied: Resolve system health failures first" in h.api.texts()


def test_takeoff_before_ready_is_taken_and_the_arming_after_it_refused(
    make_harness: HarnessFactory,
) -> None:
    # Commander: NAV_TAKEOFF is a mode change, always allowed while disarmed; canArm refuses
    h = make_harness(ready=False)
    h.run(2.0)
    h.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    assert h.last_ack(mavlink.MAV_CMD_NAV_TAKEOFF) == ACCEPTED
    assert h.vehicle.mode_name == "AUTO_TAKEOFF"
    h.arm()
    assert h.last_ack(ARM) == TEMPORARILY_REJECTED
    assert "Arming denied: Resolve system health failures first" in h.api.texts()
    assert not h.vehicle.armed


def test_arming_in_offboard_without_signal_is_refused(harness: Harness) -> None:
    harness.set_mode(modes.OFFBOARD)
    assert harness.last_ack(SET_MODE) == ACCEPTED  # disarmed: any known mode is accepted
    harness.arm()
    assert harness.last_ack(ARM) == TEMPORARILY_REJECTED
    assert "Arming denied: Resolve system health failures first" in harness.api.texts()


def test_arming_in_a_mode_preventing_arming_is_refused(harness: Harness) -> None:
    # mode_requirements.cpp mode_req_prevent_arming: "Mode not suitable for arming"
    harness.set_mode(modes.AUTO_RTL)
    assert harness.last_ack(SET_MODE) == ACCEPTED  # disarmed: any known mode is accepted
    harness.arm()
    assert harness.last_ack(ARM) == TEMPORARILY_REJECTED
    harness.set_mode(modes.AUTO_LOITER)
    harness.arm()
    assert harness.last_ack(ARM) == ACCEPTED


def test_disarm_in_air_needs_force(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    harness.arm()
    harness.run_until(lambda: not harness.vehicle.commander.landed, 10.0)
    harness.command_long(ARM, 0)
    assert harness.last_ack(ARM) == TEMPORARILY_REJECTED
    assert "Disarming denied: not landed" in harness.api.texts()
    harness.command_long(ARM, 0, 21196)
    assert harness.last_ack(ARM) == ACCEPTED
    assert not harness.vehicle.armed


def test_do_set_mode_is_acked_twice_accepted_first(harness: Harness) -> None:
    harness.arm()
    harness.set_mode(modes.OFFBOARD)  # armed, no setpoints: really refused
    assert [a.result for a in harness.api.acks(SET_MODE)] == [ACCEPTED, TEMPORARILY_REJECTED]
    harness.set_mode(modes.AUTO_RTL)
    assert [a.result for a in harness.api.acks(SET_MODE)][2:] == [ACCEPTED, ACCEPTED]


def test_set_mode_message_is_acked_as_do_set_mode(harness: Harness) -> None:
    harness.deliver(mavlink.MAVLink_set_mode_message(1, 1, modes.AUTO_LAND.custom_mode))
    assert [a.result for a in harness.api.acks(SET_MODE)] == [ACCEPTED, ACCEPTED]
    assert harness.vehicle.mode_name == "AUTO_LAND"


@pytest.mark.parametrize("mode", [modes.AUTO_FOLLOW_TARGET, modes.AUTO_PRECLAND,
                                  modes.AUTO_READY])
def test_unsupported_auto_sub_modes_are_temporarily_rejected(harness: Harness,
                                                            mode: modes.Px4Mode) -> None:
    harness.set_mode(mode)
    assert harness.last_ack(SET_MODE) == TEMPORARILY_REJECTED
    assert harness.vehicle.mode_name == "AUTO_LOITER"


def test_mission_mode_is_accepted_disarmed_and_refused_armed(harness: Harness) -> None:
    harness.set_mode(modes.AUTO_MISSION)
    assert harness.last_ack(SET_MODE) == ACCEPTED
    harness.set_mode(modes.AUTO_LOITER)
    harness.arm()
    harness.set_mode(modes.AUTO_MISSION)
    assert harness.last_ack(SET_MODE) == TEMPORARILY_REJECTED


def test_takeoff_switches_to_auto_takeoff(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    assert harness.last_ack(mavlink.MAV_CMD_NAV_TAKEOFF) == ACCEPTED
    assert harness.vehicle.mode_name == "AUTO_TAKEOFF"


def test_land_and_rtl_commands_switch_mode(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_NAV_LAND)
    assert harness.last_ack(mavlink.MAV_CMD_NAV_LAND) == ACCEPTED
    assert harness.vehicle.mode_name == "AUTO_LAND"
    harness.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    assert harness.vehicle.mode_name == "AUTO_RTL"


@pytest.mark.parametrize("flags", [0, 2, 3])
def test_reposition_without_exactly_change_mode_flag_is_unsupported(harness: Harness,
                                                                    flags: int) -> None:
    harness.command_long(REPOSITION, -1, flags, 0, math.nan, 47.3978, 8.5456, 500)
    assert harness.last_ack(REPOSITION) == UNSUPPORTED


def test_reposition_int_is_exact_and_keeps_nan_fields(harness: Harness) -> None:
    v = harness.vehicle
    target = v.origin.to_geodetic(30.0, -20.0, 0.0)
    harness.command_int(REPOSITION, mavlink.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, math.nan),
                        round(target.lat_deg * 1e7), round(target.lon_deg * 1e7), math.nan)
    assert harness.last_ack(REPOSITION) == ACCEPTED
    assert v.mode_name == "AUTO_LOITER"
    harness.run(0.004)
    north, east, down = v.navigator.hold_target_ned_m
    assert north == pytest.approx(30.0, abs=0.02)
    assert east == pytest.approx(-20.0, abs=0.02)
    assert down == v.truth.position_ned_m[2]


def test_reposition_long_uses_speed_yaw_in_radians_and_amsl_altitude(harness: Harness) -> None:
    v = harness.vehicle
    harness.command_long(REPOSITION, 3.0, 1, 0, math.pi / 2, math.nan, math.nan,
                         v.origin.alt_m + 15.0)
    assert harness.last_ack(REPOSITION) == ACCEPTED
    harness.arm()
    harness.run(0.1)
    assert v.navigator.hold_target_ned_m[2] == pytest.approx(-15.0, abs=1e-3)
    sp = v.last_trajectory_setpoint
    assert sp is None or (sp.yaw_rad == pytest.approx(math.pi / 2) and sp.max_speed_xy_m_s == 3.0)


def test_reposition_ends_offboard(harness: Harness) -> None:
    harness.local_ned(0b0000_1011_1111_1000, position=(0, 0, -2))
    harness.set_mode(modes.OFFBOARD)
    harness.command_long(REPOSITION, -1, 1, 0, math.nan, math.nan, math.nan, math.nan)
    assert harness.vehicle.mode_name == "AUTO_LOITER"
    assert harness.vehicle.commander.user_mode == modes.AUTO_LOITER


def test_vtol_transition_has_no_ack_on_a_multicopter(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_DO_VTOL_TRANSITION, 4)
    assert harness.api.acks() == []


def test_vtol_transition_acks_and_refuses_front_transition_in_takeoff(
    make_harness: HarnessFactory,
) -> None:
    h = make_harness("vtol")
    transition = mavlink.MAV_CMD_DO_VTOL_TRANSITION
    h.command_long(transition, 4)
    assert h.last_ack(transition) == ACCEPTED
    assert h.model.transitions == [(True, False)]
    h.command_long(transition, 3, 1)
    assert h.last_ack(transition) == ACCEPTED
    assert h.model.transitions[-1] == (False, True)
    h.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    h.command_long(transition, 4)
    assert h.last_ack(transition) == TEMPORARILY_REJECTED


def test_set_message_interval_fails_for_heartbeat_and_unknown_ids(harness: Harness) -> None:
    interval = mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
    harness.command_long(interval, mavlink.MAVLINK_MSG_ID_HEARTBEAT, 100000)
    assert harness.last_ack(interval) == FAILED
    harness.command_long(interval, 4242, 100000)
    assert harness.last_ack(interval) == FAILED
    harness.command_long(interval, mavlink.MAVLINK_MSG_ID_ALTITUDE + 100000, 100000)
    assert harness.last_ack(interval) == FAILED


@pytest.mark.parametrize(
    "msg_type",
    ["AUTOPILOT_VERSION", "CURRENT_MODE", "HOME_POSITION", "GPS_GLOBAL_ORIGIN",
     "EXTENDED_SYS_STATE", "ACTUATOR_OUTPUT_STATUS"],
)
def test_request_message_acks_then_sends_the_message(harness: Harness, msg_type: str) -> None:
    msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{msg_type}")
    harness.api.clear()
    harness.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, msg_id)
    kinds = [m.get_type() for m in harness.api.sent if m.get_type() in ("COMMAND_ACK", msg_type)]
    assert kinds == ["COMMAND_ACK", msg_type]
    assert harness.last_ack(mavlink.MAV_CMD_REQUEST_MESSAGE) == ACCEPTED


def test_current_mode_shows_current_and_intended_mode(harness: Harness) -> None:
    harness.set_mode(modes.AUTO_RTL)
    harness.api.clear()  # CURRENT_MODE also streams (0.5 Hz): keep only the answer
    harness.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_CURRENT_MODE)
    (current,) = harness.api.of_type("CURRENT_MODE")
    assert current.custom_mode == modes.AUTO_RTL.custom_mode
    assert current.intended_custom_mode == modes.AUTO_RTL.custom_mode
    assert current.standard_mode == mavlink.MAV_STANDARD_MODE_SAFE_RECOVERY


def test_set_gps_global_origin_is_answered_with_gps_global_origin(harness: Harness) -> None:
    harness.deliver(mavlink.MAVLink_set_gps_global_origin_message(1, 473000000, 85000000,
                                                                   400000))
    assert harness.api.acks() == []
    (origin,) = harness.api.of_type("GPS_GLOBAL_ORIGIN")
    assert (origin.latitude, origin.longitude, origin.altitude) == (473000000, 85000000, 400000)


def test_do_set_home_current_and_given_position(harness: Harness) -> None:
    v = harness.vehicle
    harness.command_long(mavlink.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, 47.398, 8.546, 495.0)
    assert harness.last_ack(mavlink.MAV_CMD_DO_SET_HOME) == ACCEPTED
    assert v.commander.home.lat_deg == pytest.approx(47.398, abs=1e-5)
    assert v.commander.home.alt_m == 495.0
    home_msgs = harness.api.of_type("HOME_POSITION")
    assert home_msgs
    assert home_msgs[-1].latitude == pytest.approx(473980000, abs=100)
    harness.command_long(mavlink.MAV_CMD_DO_SET_HOME, 1)
    assert v.commander.home.position_ned_m == pytest.approx(v.truth.position_ned_m)


def test_repeated_commands_are_safe(harness: Harness) -> None:
    for _ in range(3):
        harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
        harness.arm()
    assert [a.result for a in harness.api.acks(ARM)] == [ACCEPTED] * 3
    assert harness.vehicle.mode_name == "AUTO_TAKEOFF"
    assert harness.vehicle.armed


def test_protocol_version_request_is_answered_with_mavlink_2(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1, target_system=0)
    assert harness.last_ack(mavlink.MAV_CMD_REQUEST_PROTOCOL_VERSION) == ACCEPTED
    (frame,) = harness.api.of_type("UNKNOWN_300")  # not in pymavlink's generated dialect
    data = bytes(frame.data)
    payload = data[10:-2] + bytes(22)  # MAVLink 2 trims trailing zero bytes
    assert struct.unpack_from("<HHH", payload) == (200, 100, 200)
    crc = mavlink.x25crc(data[1:-2])
    crc.accumulate(bytes([217]))  # PROTOCOL_VERSION's CRC_EXTRA in common.xml
    assert struct.unpack("<H", data[-2:])[0] == crc.crc
