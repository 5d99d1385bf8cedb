"""Offboard setpoint handling, one test per rule of PX4_NOTES "Offboard setpoints"."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.lib import modes
from sim.lib.topics import AttitudeSetpoint, RatesSetpoint, TrajectorySetpoint
from tests.sim.conftest import Harness, HarnessFactory

POSITION_ONLY = 0b0000_1011_1111_1000  # position and yaw: velocity, accel, yaw rate ignored
VELOCITY_ONLY = 0b0000_1101_1100_0111  # ignore position, acceleration, yaw
ACCEL_ONLY = 0b0000_1100_0011_1111
NOTHING = 0b0000_1101_1111_1111
FORCE = 512


def offboard_setpoint(h: Harness) -> TrajectorySetpoint:
    sp = h.vehicle.commander.offboard.setpoint
    assert isinstance(sp, TrajectorySetpoint)
    return sp


def test_setpoint_is_never_acked(harness: Harness) -> None:
    harness.local_ned(POSITION_ONLY, position=(1.0, 2.0, -3.0))
    assert harness.api.sent == [] or harness.api.acks() == []


def test_setpoint_counts_as_proof_of_life_in_any_mode(harness: Harness) -> None:
    assert harness.vehicle.mode_name == "AUTO_LOITER"
    harness.local_ned(POSITION_ONLY, position=(1.0, 2.0, -3.0))
    assert harness.vehicle.commander.offboard_signal_fresh()
    assert harness.vehicle.mode_name == "AUTO_LOITER"


def test_ignore_bits_make_axes_nan(harness: Harness) -> None:
    harness.local_ned(POSITION_ONLY | 2, position=(1.0, 2.0, -3.0))  # also ignore y
    sp = offboard_setpoint(harness)
    assert sp.position_ned_m[0] == 1.0
    assert math.isnan(sp.position_ned_m[1])
    assert sp.position_ned_m[2] == -3.0
    assert all(math.isnan(v) for v in sp.velocity_ned_m_s + sp.acceleration_ned_m_s2)
    assert sp.yaw_rad == 0.0
    assert math.isnan(sp.yawspeed_rad_s)


@pytest.mark.parametrize("frame", [7, 9, 3])
def test_offset_and_other_frames_are_refused_with_statustext(harness: Harness, frame: int) -> None:
    harness.local_ned(POSITION_ONLY, frame=frame, position=(1.0, 0.0, -2.0))
    assert harness.vehicle.commander.offboard.setpoint is None
    assert f"SET_POSITION_TARGET_LOCAL_NED coordinate frame {frame} unsupported" in (
        harness.api.texts())


def test_body_ned_ignores_position_and_rotates_velocity_by_yaw(harness: Harness) -> None:
    harness.vehicle.model.reset([0.0, 0.0, 0.0], math.pi / 2)  # facing east
    harness.local_ned(0b0000_1100_0000_0000 | 0b111000000, frame=mavlink.MAV_FRAME_BODY_NED,
                      position=(5.0, 5.0, -5.0), velocity=(1.0, 0.0, 0.5))
    sp = offboard_setpoint(harness)
    assert all(math.isnan(v) for v in sp.position_ned_m)
    assert sp.velocity_ned_m_s == pytest.approx([0.0, 1.0, 0.5], abs=1e-9)


def test_body_ned_rotates_acceleration_by_full_attitude(harness: Harness) -> None:
    truth = harness.vehicle.truth
    half = math.pi / 4  # 90° roll
    truth.q_wxyz[:] = [math.cos(half), math.sin(half), 0.0, 0.0]
    harness.local_ned(ACCEL_ONLY, frame=mavlink.MAV_FRAME_BODY_NED, accel=(0.0, 1.0, 0.0))
    sp = offboard_setpoint(harness)
    assert sp.acceleration_ned_m_s2 == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)


def test_force_bit_with_acceleration_is_refused(harness: Harness) -> None:
    harness.local_ned(ACCEL_ONLY | FORCE, accel=(1.0, 0.0, 0.0))
    assert harness.vehicle.commander.offboard.setpoint is None
    assert "SET_POSITION_TARGET_LOCAL_NED force not supported" in harness.api.texts()


def test_setpoint_with_nothing_usable_is_dropped_as_invalid(harness: Harness) -> None:
    harness.local_ned(NOTHING)
    assert harness.vehicle.commander.offboard.setpoint is None
    assert "SET_POSITION_TARGET_LOCAL_NED invalid" in harness.api.texts()


def test_setpoint_for_another_system_or_component_is_ignored(harness: Harness) -> None:
    harness.local_ned(POSITION_ONLY, target_system=2)
    harness.local_ned(POSITION_ONLY, target_component=42)
    assert harness.vehicle.commander.offboard.setpoint is None
    harness.local_ned(POSITION_ONLY, target_component=0)
    assert harness.vehicle.commander.offboard.setpoint is not None


def _global_int(h: Harness, frame: int, lat_deg: float, lon_deg: float, alt_m: float,
                type_mask: int = POSITION_ONLY) -> None:
    h.deliver(mavlink.MAVLink_set_position_target_global_int_message(
        0, 1, 1, frame, type_mask, round(lat_deg * 1e7), round(lon_deg * 1e7), alt_m,
        0, 0, 0, 0, 0, 0, 0, 0))


def test_global_int_position_is_projected_around_the_local_origin(harness: Harness) -> None:
    origin = harness.vehicle.origin
    target = origin.to_geodetic(10.0, -5.0, -20.0)
    _global_int(harness, mavlink.MAV_FRAME_GLOBAL_INT, target.lat_deg, target.lon_deg,
                target.alt_m)
    sp = offboard_setpoint(harness)
    assert sp.position_ned_m == pytest.approx([10.0, -5.0, -20.0], abs=0.02)


def test_global_relative_alt_is_above_home(harness: Harness) -> None:
    origin = harness.vehicle.origin
    target = origin.to_geodetic(3.0, 4.0, 0.0)
    _global_int(harness, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, target.lat_deg,
                target.lon_deg, 12.0)
    home_down = harness.vehicle.commander.home.position_ned_m[2]
    assert offboard_setpoint(harness).position_ned_m[2] == pytest.approx(home_down - 12.0)


def test_global_position_with_an_ignored_axis_is_not_used(harness: Harness) -> None:
    _global_int(harness, mavlink.MAV_FRAME_GLOBAL_INT, 47.4, 8.5, 500.0,
                type_mask=POSITION_ONLY | 4)
    assert harness.vehicle.commander.offboard.setpoint is None
    assert "SET_POSITION_TARGET_GLOBAL_INT invalid" in harness.api.texts()


def test_global_setpoint_dropped_silently_without_global_position(
    make_harness: HarnessFactory,
) -> None:
    h = make_harness(ready=False)
    h.run(2.0)  # booted, no GPS fix yet
    _global_int(h, mavlink.MAV_FRAME_GLOBAL_INT, 47.4, 8.5, 500.0)
    assert h.vehicle.commander.offboard.setpoint is None
    assert h.api.texts() == []


def test_global_frame_outside_the_three_accepted_is_refused(harness: Harness) -> None:
    _global_int(harness, mavlink.MAV_FRAME_LOCAL_NED, 47.4, 8.5, 500.0)
    assert "SET_POSITION_TARGET_GLOBAL_INT coordinate frame 1 unsupported" in harness.api.texts()


def _attitude_target(h: Harness, type_mask: int, q: tuple[float, float, float, float],
                     rates: tuple[float, float, float], thrust: float) -> None:
    h.deliver(mavlink.MAVLink_set_attitude_target_message(0, 1, 1, type_mask, q, *rates, thrust))


def test_attitude_target_gives_attitude_and_thrust_along_minus_z(harness: Harness) -> None:
    _attitude_target(harness, 0b111, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.6)
    sp = harness.vehicle.commander.offboard.setpoint
    assert isinstance(sp, AttitudeSetpoint)
    assert sp.thrust_body == pytest.approx((0.0, 0.0, -0.6))


def test_body_rates_take_priority_over_attitude(harness: Harness) -> None:
    _attitude_target(harness, 0, (1.0, 0.0, 0.0, 0.0), (0.1, 0.2, 0.3), 0.5)
    sp = harness.vehicle.commander.offboard.setpoint
    assert isinstance(sp, RatesSetpoint)
    assert sp.rates_rad_s == pytest.approx((0.1, 0.2, 0.3))


def test_attitude_target_with_attitude_and_rates_ignored_is_invalid(harness: Harness) -> None:
    _attitude_target(harness, 0b1000_0111, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.5)
    assert harness.vehicle.commander.offboard.setpoint is None


def test_fixed_wing_thrust_is_along_plus_x(make_harness: HarnessFactory) -> None:
    h = make_harness("plane")
    _attitude_target(h, 0b111, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.7)
    sp = h.vehicle.commander.offboard.setpoint
    assert isinstance(sp, AttitudeSetpoint)
    assert sp.thrust_body == pytest.approx((0.7, 0.0, 0.0))


def test_setpoints_before_offboard_are_only_used_once_in_offboard(harness: Harness) -> None:
    harness.arm()
    harness.local_ned(POSITION_ONLY, position=(0.0, 0.0, -3.0))
    harness.run(0.2)
    assert harness.vehicle.truth.position_ned_m[2] == 0.0  # Hold on the ground: idle
    harness.set_mode(modes.OFFBOARD)
    for _ in range(30):
        harness.local_ned(POSITION_ONLY, position=(0.0, 0.0, -3.0))
        harness.run(0.1)
    assert harness.vehicle.mode_name == "OFFBOARD"
    assert harness.vehicle.truth.position_ned_m[2] == pytest.approx(-3.0, abs=0.3)


def test_position_plus_velocity_passes_velocity_as_feed_forward(harness: Harness) -> None:
    harness.local_ned(0b0000_1101_1100_0000, position=(1.0, 2.0, -3.0), velocity=(0.5, 0, 0))
    sp = offboard_setpoint(harness)
    assert sp.position_ned_m == [1.0, 2.0, -3.0]
    assert sp.velocity_ned_m_s == [0.5, 0.0, 0.0]
