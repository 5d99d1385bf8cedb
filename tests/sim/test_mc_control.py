"""Multicopter cascade on the SIH quad, flown in simulated time (PX4_NOTES' observed timings)."""

from __future__ import annotations

import math

import pytest

from sim.lib.quat import euler_from_quat, quat_from_euler, yaw_from_quat
from sim.lib.topics import AttitudeSetpoint, RatesSetpoint, TrajectorySetpoint
from sim.models.airframes import AirframeModel, StaticParams, default_params, make_airframe
from sim.models.sim_run import fly, fly_peak

HOVER_DOWN_M = -5.0


def _hovering(airframe: str = "quad", params: StaticParams | None = None) -> AirframeModel:
    model = make_airframe(airframe, params or default_params(airframe))
    model.reset([0.0, 0.0, 0.0], 0.0)
    fly(model, TrajectorySetpoint(position_ned_m=[0.0, 0.0, HOVER_DOWN_M]), 8.0)
    return model


def _distance_to(model: AirframeModel, target: list[float]) -> float:
    return math.dist(model.truth.position_ned_m, target)


def _speed_xy(model: AirframeModel) -> float:
    v = model.truth.velocity_ned_m_s
    return math.hypot(v[0], v[1])


def _tilt_deg(model: AirframeModel) -> float:
    roll, pitch, _ = euler_from_quat(model.truth.q_wxyz)
    return math.degrees(math.acos(max(-1.0, min(1.0, math.cos(roll) * math.cos(pitch)))))


def test_takeoff_climbs_no_faster_than_mpc_z_vel_max_up() -> None:
    quad = make_airframe("quad", default_params("quad"))
    quad.reset([0.0, 0.0, 0.0], 0.0)
    target = [0.0, 0.0, -10.0]
    fastest = fly_peak(
        quad, TrajectorySetpoint(position_ned_m=target), 10.0,
        lambda: -quad.truth.velocity_ned_m_s[2],
    )
    assert _distance_to(quad, target) < 0.3
    assert 2.5 <= fastest <= 3.0 * 1.1


@pytest.mark.parametrize("airframe", ["quad", "hexa", "octo"])
def test_offboard_move_of_5_8_m_settles_like_px4_sih(airframe: str) -> None:
    model = _hovering(airframe)
    target = [5.8, 0.0, HOVER_DOWN_M]
    within = fly(
        model, TrajectorySetpoint(position_ned_m=target), 10.0,
        until=lambda: _distance_to(model, target) < 0.7,
    )
    # PX4 v1.16 SIH through MAVSDK: within 0.7 m after ≈ 2.5 s
    assert within is not None
    assert 1.5 <= within <= 3.2
    fly(model, TrajectorySetpoint(position_ned_m=target), 12.0)
    assert _distance_to(model, target) < 0.1


def test_holds_position_within_centimetres_in_still_air() -> None:
    quad = _hovering()
    target = [0.0, 0.0, HOVER_DOWN_M]
    worst = fly_peak(
        quad, TrajectorySetpoint(position_ned_m=target), 10.0, lambda: _distance_to(quad, target)
    )
    assert worst < 0.05


def test_velocity_setpoint_is_tracked() -> None:
    quad = _hovering()
    sp = TrajectorySetpoint(velocity_ned_m_s=[0.0, 2.0, 0.0])
    t_fast = fly(quad, sp, 10.0, until=lambda: quad.truth.velocity_ned_m_s[1] >= 1.5)
    # SIH_KDV drag is worked off by the velocity integrator: 1.5 m/s early, 2 m/s later
    assert t_fast is not None
    assert t_fast <= 3.7
    assert fly(quad, sp, 15.0, until=lambda: quad.truth.velocity_ned_m_s[1] >= 1.9) is not None
    fly(quad, sp, 3.0)
    assert quad.truth.velocity_ned_m_s[1] == pytest.approx(2.0, abs=0.1)
    assert abs(quad.truth.velocity_ned_m_s[0]) < 0.1
    assert quad.truth.position_ned_m[2] == pytest.approx(HOVER_DOWN_M, abs=0.3)
    assert quad.truth.airspeed_m_s == pytest.approx(2.0, abs=0.15)


def test_zero_velocity_stops_the_vehicle_quickly() -> None:
    quad = _hovering()
    fly(quad, TrajectorySetpoint(velocity_ned_m_s=[2.0, 0.0, 0.0]), 4.0)
    assert _speed_xy(quad) > 1.5
    stopped = fly(
        quad, TrajectorySetpoint(velocity_ned_m_s=[0.0, 0.0, 0.0]), 5.0,
        until=lambda: _speed_xy(quad) < 0.5,
    )
    assert stopped is not None
    assert stopped < 1.2


def test_yaw_setpoint_turns_the_vehicle_and_keeps_position() -> None:
    quad = _hovering()
    target = [0.0, 0.0, HOVER_DOWN_M]
    sp = TrajectorySetpoint(position_ned_m=target, yaw_rad=math.radians(90.0))
    turned = fly(
        quad, sp, 6.0,
        until=lambda: abs(math.degrees(yaw_from_quat(quad.truth.q_wxyz)) - 90.0) < 3.0,
    )
    assert turned is not None
    assert turned < 3.0
    fly(quad, sp, 4.0)
    assert math.degrees(yaw_from_quat(quad.truth.q_wxyz)) == pytest.approx(90.0, abs=1.0)
    assert _distance_to(quad, target) < 0.1


def test_nan_yaw_holds_the_current_heading() -> None:
    quad = make_airframe("quad", default_params("quad"))
    quad.reset([0.0, 0.0, 0.0], math.radians(-120.0))
    fly(quad, TrajectorySetpoint(position_ned_m=[4.0, 3.0, -5.0]), 10.0)
    assert math.degrees(yaw_from_quat(quad.truth.q_wxyz)) == pytest.approx(-120.0, abs=1.0)


def test_yawspeed_setpoint_spins_at_that_rate() -> None:
    quad = _hovering()
    sp = TrajectorySetpoint(position_ned_m=[0.0, 0.0, HOVER_DOWN_M], yawspeed_rad_s=0.5)
    fly(quad, sp, 3.0)
    assert quad.truth.rates_body_rad_s[2] == pytest.approx(0.5, abs=0.05)


def test_velocity_feed_forward_reduces_tracking_lag() -> None:
    def tracking_error(with_feed_forward: bool) -> float:
        quad = _hovering()
        speed = 3.0
        worst = 0.0
        for k in range(1, 5 * 50 + 1):
            t = k * 0.02
            target = [speed * t, 0.0, HOVER_DOWN_M]
            ff = [speed, 0.0, 0.0] if with_feed_forward else [math.nan] * 3
            sp = TrajectorySetpoint(position_ned_m=target, velocity_ned_m_s=ff)
            fly(quad, sp, 0.02)
            if t > 3.0:
                worst = max(worst, _distance_to(quad, target))
        return worst

    with_ff, without_ff = tracking_error(True), tracking_error(False)
    assert with_ff < 0.6 * without_ff


def test_acceleration_feed_forward_improves_circle_tracking() -> None:
    radius_m, omega_rad_s = 5.0, 0.6

    def worst_error(with_acceleration: bool) -> float:
        quad = _hovering()
        fly(quad, TrajectorySetpoint(position_ned_m=[radius_m, 0.0, HOVER_DOWN_M]), 4.0)
        worst = 0.0
        for k in range(1, 12 * 50 + 1):
            t = k * 0.02
            c, s = math.cos(omega_rad_s * t), math.sin(omega_rad_s * t)
            target = [radius_m * c, radius_m * s, HOVER_DOWN_M]
            velocity = [-radius_m * omega_rad_s * s, radius_m * omega_rad_s * c, 0.0]
            accel = [-radius_m * omega_rad_s**2 * c, -radius_m * omega_rad_s**2 * s, 0.0]
            sp = TrajectorySetpoint(
                position_ned_m=target,
                velocity_ned_m_s=velocity,
                acceleration_ned_m_s2=accel if with_acceleration else [math.nan] * 3,
            )
            fly(quad, sp, 0.02)
            if t > 5.0:
                worst = max(worst, _distance_to(quad, target))
        return worst

    assert worst_error(True) < 0.9 * worst_error(False)


def test_acceleration_feed_forward_is_applied() -> None:
    quad = _hovering()
    sp = TrajectorySetpoint(acceleration_ned_m_s2=[2.0, 0.0, 0.0])
    fly(quad, sp, 1.0)
    assert quad.truth.velocity_ned_m_s[0] > 1.0
    assert abs(quad.truth.velocity_ned_m_s[1]) < 0.1


def test_setpoint_speed_limit_caps_horizontal_speed() -> None:
    quad = _hovering()
    sp = TrajectorySetpoint(position_ned_m=[60.0, 0.0, HOVER_DOWN_M], max_speed_xy_m_s=2.5)
    fastest = fly_peak(quad, sp, 10.0, lambda: _speed_xy(quad))
    assert 2.2 < fastest <= 2.5 * 1.1


def test_mpc_xy_vel_max_caps_speed_and_takes_effect_at_once() -> None:
    params = default_params("quad")
    quad = _hovering(params=params)
    params.values["MPC_XY_VEL_MAX"] = 1.5
    fastest = fly_peak(
        quad, TrajectorySetpoint(position_ned_m=[0.0, 60.0, HOVER_DOWN_M]), 10.0,
        lambda: _speed_xy(quad),
    )
    assert 1.3 < fastest <= 1.5 * 1.1


def test_descent_is_limited_to_mpc_z_vel_max_dn() -> None:
    quad = make_airframe("quad", default_params("quad"))
    quad.reset([0.0, 0.0, 0.0], 0.0)
    fly(quad, TrajectorySetpoint(position_ned_m=[0.0, 0.0, -20.0]), 12.0)
    fastest = fly_peak(
        quad, TrajectorySetpoint(position_ned_m=[0.0, 0.0, -1.0]), 8.0,
        lambda: quad.truth.velocity_ned_m_s[2],
    )
    assert 1.3 < fastest <= 1.5 * 1.1


def test_tilt_never_exceeds_mpc_tiltmax_air() -> None:
    quad = _hovering()
    worst = fly_peak(
        quad, TrajectorySetpoint(acceleration_ned_m_s2=[30.0, -30.0, 0.0]), 1.5,
        lambda: _tilt_deg(quad),
    )
    assert 40.0 < worst <= 45.0 + 3.0


def test_attitude_setpoint_bypasses_position_control() -> None:
    quad = _hovering()
    hover = 9.80665 / 20.0
    q_sp = quat_from_euler(math.radians(15.0), 0.0, 0.0)
    fly(quad, AttitudeSetpoint(q_wxyz=q_sp, thrust_body=(0.0, 0.0, -hover / math.cos(0.26))), 1.0)
    roll, pitch, _ = euler_from_quat(quad.truth.q_wxyz)
    assert math.degrees(roll) == pytest.approx(15.0, abs=1.0)
    assert abs(math.degrees(pitch)) < 1.0
    # rolled right, the thrust pushes the vehicle east
    assert quad.truth.velocity_ned_m_s[1] > 0.5


def test_rates_setpoint_drives_body_rates() -> None:
    quad = _hovering()
    fly(quad, RatesSetpoint(rates_rad_s=(0.0, 0.0, 1.0), thrust_body=(0.0, 0.0, -0.49)), 2.0)
    assert quad.truth.rates_body_rad_s[2] == pytest.approx(1.0, abs=0.1)
    assert abs(quad.truth.rates_body_rad_s[0]) < 0.05
