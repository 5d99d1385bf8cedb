"""Stick input on the simulated vehicle: MANUAL_CONTROL read as PX4 reads it, COM_RC_IN_MODE,
stick -> setpoint per manual mode, mode and arming refusals, and the manual-control-loss
failsafe."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.flight.manual_control import (
    SOURCE_MAVLINK_0,
    ManualFlight,
    RcInMode,
    StickSample,
    expo_deadzone,
    stick_sample,
)
from sim.lib import modes
from sim.lib.params import PX4_DEFAULTS, ParamStore
from sim.lib.topics import AttitudeSetpoint, TrajectorySetpoint, VehicleStateTruth
from tests.sim.conftest import Harness, RecordingLink

SET_MODE = mavlink.MAV_CMD_DO_SET_MODE
ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
RATE_HZ = 25.0


def sticks(h: Harness, x: int = 0, y: int = 0, z: int = 500, r: int = 0,
           target: int = 1, link: RecordingLink | None = None) -> None:
    h.deliver(mavlink.MAVLink_manual_control_message(target, x, y, z, r, 0), link)


def fly_sticks(h: Harness, seconds: float, **axes: int) -> None:
    for _ in range(round(seconds * RATE_HZ)):
        sticks(h, **axes)
        h.run(1.0 / RATE_HZ)


def airborne_in_hold(h: Harness) -> None:
    h.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7)
    h.arm()
    h.run_until(lambda: h.vehicle.mode_name == "AUTO_LOITER", 20.0)
    h.run(1.0)


def in_posctl(h: Harness) -> None:
    airborne_in_hold(h)
    fly_sticks(h, 0.2)
    h.set_mode(modes.POSCTL)
    assert h.last_ack(SET_MODE) == mavlink.MAV_RESULT_ACCEPTED
    fly_sticks(h, 0.5)


def params() -> ParamStore:
    return ParamStore(dict(PX4_DEFAULTS))


def sample(roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0,
           throttle: float = 0.0) -> StickSample:
    return StickSample(roll, pitch, yaw, throttle, 0.0, SOURCE_MAVLINK_0)


def test_manual_control_fields_read_as_px4_reads_them() -> None:
    s = stick_sample(500, -250, 1000, 1000, 1.0, SOURCE_MAVLINK_0)
    assert (s.pitch, s.roll, s.throttle, s.yaw) == (0.5, -0.25, 1.0, 1.0)
    assert stick_sample(0, 0, 0, 0, 0.0, SOURCE_MAVLINK_0).throttle == -1.0
    assert stick_sample(0, 0, 500, 0, 0.0, SOURCE_MAVLINK_0).throttle == 0.0
    # out of range: the axis stays at its zero
    off = stick_sample(1001, -1001, 1001, 2000, 0.0, SOURCE_MAVLINK_0)
    assert (off.pitch, off.roll, off.throttle, off.yaw) == (0.0, 0.0, 0.0, 0.0)


def test_expo_deadzone_is_px4s() -> None:
    assert expo_deadzone(0.05, 0.6, 0.1) == 0.0
    assert expo_deadzone(1.0, 0.6, 0.1) == pytest.approx(1.0)
    assert expo_deadzone(-1.0, 0.6, 0.1) == pytest.approx(-1.0)
    # half stick past the deadzone: (0.5-0.1)/0.9 = 0.444, then 0.4·x + 0.6·x³
    x = 0.4 / 0.9
    assert expo_deadzone(0.5, 0.6, 0.1) == pytest.approx(0.4 * x + 0.6 * x**3)


def test_posctl_full_forward_stick_is_mpc_vel_manual_along_the_heading() -> None:
    p = params()
    truth = VehicleStateTruth(on_ground=False)
    yaw = math.radians(90.0)  # facing east
    truth.q_wxyz[:] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
    sp = ManualFlight(p).setpoint(modes.POSCTL, sample(pitch=1.0), truth, 0.004, landed=False)
    assert isinstance(sp, TrajectorySetpoint)
    assert sp.velocity_ned_m_s[0] == pytest.approx(0.0, abs=1e-9)
    assert sp.velocity_ned_m_s[1] == pytest.approx(p.get("MPC_VEL_MANUAL"))
    assert math.isnan(sp.position_ned_m[0])


def test_posctl_throttle_is_climb_rate_up_and_down_limits() -> None:
    p = params()
    truth = VehicleStateTruth(on_ground=False)
    flight = ManualFlight(p)
    up = flight.setpoint(modes.POSCTL, sample(throttle=1.0), truth, 0.004, landed=False)
    down = flight.setpoint(modes.POSCTL, sample(throttle=-1.0), truth, 0.004, landed=False)
    assert isinstance(up, TrajectorySetpoint)
    assert isinstance(down, TrajectorySetpoint)
    assert up.velocity_ned_m_s[2] == pytest.approx(-p.get("MPC_Z_VEL_MAX_UP"))
    assert down.velocity_ned_m_s[2] == pytest.approx(p.get("MPC_Z_VEL_MAX_DN"))


def test_posctl_centred_sticks_lock_position_and_altitude() -> None:
    truth = VehicleStateTruth(position_ned_m=[3.0, -2.0, -10.0], on_ground=False)
    sp = ManualFlight(params()).setpoint(modes.POSCTL, sample(), truth, 0.004, landed=False)
    assert isinstance(sp, TrajectorySetpoint)
    assert sp.position_ned_m == [3.0, -2.0, -10.0]
    assert sp.velocity_ned_m_s == [0.0, 0.0, 0.0]


def test_altctl_stick_is_tilt_acceleration_and_climb_rate() -> None:
    p = params()
    truth = VehicleStateTruth(on_ground=False)
    sp = ManualFlight(p).setpoint(modes.ALTCTL, sample(roll=1.0, throttle=1.0), truth, 0.004,
                                  landed=False)
    assert isinstance(sp, TrajectorySetpoint)
    tilt = math.radians(p.get("MPC_MAN_TILT_MAX"))
    assert sp.acceleration_ned_m_s2[1] == pytest.approx(9.80665 * math.tan(tilt), rel=1e-3)
    assert math.isnan(sp.velocity_ned_m_s[0])
    assert sp.velocity_ned_m_s[2] == pytest.approx(-p.get("MPC_Z_VEL_MAX_UP"))


def test_stabilized_stick_is_attitude_and_mid_throttle_is_hover() -> None:
    p = params()
    truth = VehicleStateTruth(on_ground=False)
    sp = ManualFlight(p).setpoint(modes.STABILIZED, sample(pitch=1.0), truth, 0.004,
                                  landed=False)
    assert isinstance(sp, AttitudeSetpoint)
    w, x, y, z = sp.q_wxyz
    pitch = math.asin(2.0 * (w * y - z * x))
    assert pitch == pytest.approx(-math.radians(p.get("MPC_MAN_TILT_MAX")))  # nose down
    assert -sp.thrust_body[2] == pytest.approx(p.get("MPC_THR_HOVER"))


def test_landed_with_low_throttle_keeps_motors_idle() -> None:
    truth = VehicleStateTruth()
    flight = ManualFlight(params())
    assert flight.setpoint(modes.POSCTL, sample(throttle=-1.0), truth, 0.004, landed=True) is None
    assert flight.setpoint(modes.POSCTL, sample(throttle=1.0), truth, 0.004,
                           landed=True) is not None


def test_posctl_refused_in_flight_without_stick_input_in_px4_words(harness: Harness) -> None:
    airborne_in_hold(harness)
    harness.set_mode(modes.POSCTL)
    assert harness.last_ack(SET_MODE) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    assert "Switching to Position is currently not available" in harness.api.texts()
    assert harness.vehicle.mode_name == "AUTO_LOITER"


def test_arming_in_posctl_refused_without_sticks_allowed_with_them(harness: Harness) -> None:
    harness.set_mode(modes.POSCTL)
    assert harness.last_ack(SET_MODE) == mavlink.MAV_RESULT_ACCEPTED  # disarmed: accepted
    harness.run(0.1)
    harness.arm()
    assert harness.last_ack(ARM) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    fly_sticks(harness, 0.2, z=0)
    harness.arm()
    assert harness.last_ack(ARM) == mavlink.MAV_RESULT_ACCEPTED


def test_posctl_flies_where_the_stick_points_and_climbs_from_the_ground(
    harness: Harness,
) -> None:
    harness.set_mode(modes.POSCTL)
    fly_sticks(harness, 0.2, z=0)
    harness.arm()
    fly_sticks(harness, 2.0, z=1000)  # full throttle: take off and climb
    assert harness.vehicle.truth.position_ned_m[2] < -2.0
    fly_sticks(harness, 2.0, x=0, y=1000)  # right stick: east (yaw 0 = facing north)
    north, east, _ = harness.vehicle.truth.position_ned_m
    assert east > 3.0
    assert abs(north) < 0.5
    fly_sticks(harness, 3.0)  # centred: it stops and holds
    held = list(harness.vehicle.truth.position_ned_m)
    fly_sticks(harness, 2.0)
    assert math.dist(held, harness.vehicle.truth.position_ned_m) < 0.3


@pytest.mark.parametrize(
    ("rc_in_mode", "taken"),
    [(RcInMode.RC_TRANSMITTER_ONLY, False), (RcInMode.JOYSTICK_ONLY, True),
     (RcInMode.RC_AND_JOYSTICK_WITH_FALLBACK, True), (RcInMode.RC_OR_JOYSTICK_KEEP_FIRST, True),
     (RcInMode.STICK_INPUT_DISABLED, False)],
)
def test_com_rc_in_mode_decides_whether_mavlink_sticks_count(
    harness: Harness, rc_in_mode: RcInMode, taken: bool
) -> None:
    harness.vehicle.params.set("COM_RC_IN_MODE", int(rc_in_mode))
    sticks(harness)
    assert harness.vehicle.commander.manual_control_lost() is not taken


def test_keep_first_ignores_a_second_link_until_reboot(harness: Harness) -> None:
    harness.vehicle.params.set("COM_RC_IN_MODE", int(RcInMode.RC_OR_JOYSTICK_KEEP_FIRST))
    sticks(harness, x=300, link=harness.api)
    harness.run(1.0)  # the first source timed out...
    sticks(harness, x=-300, link=harness.gcs)  # ...yet another source is still not taken
    assert harness.vehicle.commander.manual_control_lost()
    harness.vehicle.params.set("COM_RC_IN_MODE", int(RcInMode.RC_AND_JOYSTICK_WITH_FALLBACK))
    sticks(harness, x=-300, link=harness.gcs)
    assert not harness.vehicle.commander.manual_control_lost()


def test_sticks_for_another_system_are_dropped(harness: Harness) -> None:
    sticks(harness, target=7)
    assert harness.vehicle.commander.manual_control_lost()
    sticks(harness, target=0)
    assert not harness.vehicle.commander.manual_control_lost()


def test_sticks_lost_after_com_rc_loss_t(harness: Harness) -> None:
    sticks(harness)
    harness.run(0.45)
    assert not harness.vehicle.commander.manual_control_lost()
    harness.run(0.1)
    assert harness.vehicle.commander.manual_control_lost()


def test_manual_control_loss_holds_then_returns_after_com_fail_act_t(harness: Harness) -> None:
    in_posctl(harness)
    took = harness.run_until(lambda: harness.vehicle.mode_name != "POSCTL", 2.0)
    assert 0.4 <= took <= 0.7, took  # COM_RC_LOSS_T 0.5 s
    assert harness.vehicle.mode_name == "AUTO_LOITER"
    assert "Failsafe activated: entering Hold for 5 seconds" in harness.api.texts()
    took = harness.run_until(lambda: harness.vehicle.mode_name != "AUTO_LOITER", 7.0)
    assert took == pytest.approx(5.0, abs=0.1)
    assert harness.vehicle.mode_name == "AUTO_RTL"  # NAV_RCL_ACT 2
    assert harness.vehicle.commander.user_mode == modes.POSCTL


def test_sticks_missing_at_arming_are_not_a_failsafe(harness: Harness) -> None:
    airborne_in_hold(harness)
    harness.run(3.0)
    assert harness.vehicle.mode_name == "AUTO_LOITER"
    assert not harness.vehicle.commander.failsafe


def test_stick_input_disabled_never_triggers_the_loss_failsafe(harness: Harness) -> None:
    airborne_in_hold(harness)
    fly_sticks(harness, 0.5)  # sticks regained while armed
    harness.vehicle.params.set("COM_RC_IN_MODE", int(RcInMode.STICK_INPUT_DISABLED))
    harness.run(1.0)
    assert harness.vehicle.mode_name == "AUTO_LOITER"
    assert not harness.vehicle.commander.failsafe


def test_loss_exception_for_hold(harness: Harness) -> None:
    harness.vehicle.params.set("COM_RCL_EXCEPT", 2)
    airborne_in_hold(harness)
    fly_sticks(harness, 0.5)
    harness.run(1.0)
    assert not harness.vehicle.commander.failsafe
