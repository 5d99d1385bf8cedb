"""Plane: wing model with stall, runway takeoff, fly-to-and-circle guidance, course holding."""

from __future__ import annotations

import math
import random

import pytest

from sim.lib.geo import SIH_LOC_H0_M
from sim.lib.quat import Vec3
from sim.lib.topics import ControlSetpoint, RatesSetpoint, TrajectorySetpoint
from sim.models.airframes import AirframeModel, default_params, make_airframe
from sim.models.sim_run import fly, fly_peak
from sim.physics.sih_aero import SihFixedWingAero

TRIM_M_S = 15.0
LOITER_M = 80.0


def _launched(down_m: float = -40.0, speed_m_s: float = TRIM_M_S) -> AirframeModel:
    """A plane thrown level at `speed_m_s` (hand launch), heading north."""
    plane = make_airframe("plane", default_params("plane"))
    plane.reset([0.0, 0.0, down_m], 0.0)
    plane.truth.velocity_ned_m_s[0] = speed_m_s
    plane.truth.on_ground = False
    return plane


def _distance_xy(plane: AirframeModel, north_m: float, east_m: float) -> float:
    p = plane.truth.position_ned_m
    return math.hypot(p[0] - north_m, p[1] - east_m)


def _aero(alpha_deg: float, speed_m_s: float = 15.0, aileron: float = 0.0,
          elevator: float = 0.0, rudder: float = 0.0) -> tuple[Vec3, Vec3]:
    a = math.radians(alpha_deg)
    v = (speed_m_s * math.cos(a), 0.0, speed_m_s * math.sin(a))
    return SihFixedWingAero().forces_and_moments(
        v, (0.0, 0.0, 0.0), SIH_LOC_H0_M, aileron, elevator, rudder, 0.0)


def test_lift_rises_with_angle_of_attack_then_stalls() -> None:
    # SIH's wing: zero lift at -4°, every segment stalls at 20° (aero.hpp's flat plates)
    lift = {a: -_aero(a)[0][2] for a in range(-4, 31)}
    assert lift[-4] < 0.0 < lift[0]
    attached = [lift[a] for a in range(-4, 15)]
    assert attached == sorted(attached)
    assert max(lift.values()) == max(lift[a] for a in range(14, 20))
    assert lift[30] < 0.8 * max(lift.values())
    for a in range(-180, 181, 5):
        force, moment = _aero(a)
        assert all(math.isfinite(x) for x in (*force, *moment))


def test_wing_drag_opposes_motion_and_surfaces_move_the_right_way() -> None:
    force, _ = _aero(0.0)
    assert force[0] < 0.0
    assert force[2] < 0.0  # lift is up (−z body) in level flight
    assert _aero(0.0, aileron=0.5)[1][0] > 0.0
    assert _aero(0.0, elevator=0.5)[1][1] > _aero(0.0)[1][1]
    assert _aero(0.0, rudder=0.5)[1][2] > 0.0
    # statically stable in pitch: more angle of attack pitches the nose down
    assert _aero(6.0)[1][1] < _aero(0.0)[1][1] < _aero(-4.0)[1][1]


def test_plane_takes_off_from_the_runway_and_circles_the_target() -> None:
    plane = make_airframe("plane", default_params("plane"))
    plane.reset([0.0, 0.0, 0.0], 0.0)
    centre = (300.0, 0.0)
    sp = TrajectorySetpoint(position_ned_m=[centre[0], centre[1], -30.0])
    airborne = fly(plane, sp, 15.0, until=lambda: plane.truth.position_ned_m[2] < -2.0)
    assert airborne is not None
    fly(plane, sp, 40.0)
    # on the circle: radius, altitude and airspeed held
    worst_radius = fly_peak(plane, sp, 35.0, lambda: abs(_distance_xy(plane, *centre) - LOITER_M))
    assert worst_radius < 3.0
    worst_alt = fly_peak(plane, sp, 35.0, lambda: abs(plane.truth.position_ned_m[2] + 30.0))
    assert worst_alt < 1.0
    # PX4's SIH airplane cannot hold FW_AIRSPD_TRIM (15 m/s) level: SIH_KDV's drag and the
    # slipstream over the tail take its 6 N; PX4 v1.16 SITL loiters at 12-13 m/s on 90 %
    # throttle, the sim at about 14 m/s on full throttle: flying, never stalling
    assert 10.0 <= plane.truth.airspeed_m_s <= TRIM_M_S + 1.0
    assert plane.in_fixed_wing_flight


def test_loiter_radius_of_the_setpoint_overrides_nav_loiter_rad() -> None:
    plane = _launched()
    sp = TrajectorySetpoint(position_ned_m=[0.0, 150.0, -40.0], loiter_radius_m=50.0)
    fly(plane, sp, 60.0)
    worst = fly_peak(plane, sp, 25.0, lambda: abs(_distance_xy(plane, 0.0, 150.0) - 50.0))
    assert worst < 3.0


def test_nav_loiter_rad_change_takes_effect() -> None:
    params = default_params("plane")
    plane = make_airframe("plane", params)
    plane.reset([0.0, 0.0, -40.0], 0.0)
    plane.truth.velocity_ned_m_s[0] = TRIM_M_S
    params.values["NAV_LOITER_RAD"] = 120.0
    sp = TrajectorySetpoint(position_ned_m=[0.0, 0.0, -40.0])
    fly(plane, sp, 60.0)
    assert _distance_xy(plane, 0.0, 0.0) == pytest.approx(120.0, abs=4.0)


def test_velocity_setpoint_flies_that_course_and_climbs() -> None:
    plane = _launched()
    sp = TrajectorySetpoint(velocity_ned_m_s=[0.0, 14.0, -2.0])
    fly(plane, sp, 15.0)
    v = plane.truth.velocity_ned_m_s
    assert math.degrees(math.atan2(v[1], v[0])) == pytest.approx(90.0, abs=3.0)
    assert -v[2] == pytest.approx(2.0, abs=0.4)
    assert math.hypot(v[0], v[1]) == pytest.approx(14.0, abs=1.5)


def test_plane_lands_by_circling_down_at_the_setpoint_sink_rate() -> None:
    plane = _launched(down_m=-20.0)
    land = TrajectorySetpoint(position_ned_m=[0.0, 0.0, 1.0], max_speed_down_m_s=1.5)
    fly(plane, land, 5.0)
    fastest_sink = fly_peak(plane, land, 5.0, lambda: plane.truth.velocity_ned_m_s[2])
    assert fastest_sink == pytest.approx(1.5, abs=0.3)
    touchdown = fly(plane, land, 40.0, until=lambda: plane.truth.on_ground)
    assert touchdown is not None
    fly(plane, land, 20.0)
    assert plane.truth.on_ground
    assert plane.truth.position_ned_m[2] == 0.0
    assert math.hypot(*plane.truth.velocity_ned_m_s) < 0.5


def test_unpowered_plane_glides_down_and_stops_on_the_ground() -> None:
    plane = _launched(down_m=-20.0)
    fly(plane, TrajectorySetpoint(position_ned_m=[500.0, 0.0, -20.0]), 90.0, armed=False)
    assert plane.truth.position_ned_m[2] == 0.0
    assert plane.truth.on_ground
    assert math.hypot(*plane.truth.velocity_ned_m_s) < 0.5
    assert plane.actuator_outputs == [0.0, 0.0, 0.0, 0.0]


def test_outputs_are_pusher_then_surfaces_in_range() -> None:
    plane = _launched()
    fly(plane, RatesSetpoint(rates_rad_s=(0.5, 0.0, 0.0), thrust_body=(0.6, 0.0, 0.0)), 0.5)
    throttle, aileron, elevator, rudder = plane.actuator_outputs
    assert throttle == pytest.approx(0.6)
    assert aileron > 0.0
    assert all(-1.0 <= s <= 1.0 for s in (aileron, elevator, rudder))
    assert plane.truth.rates_body_rad_s[0] > 0.2


def test_plane_never_produces_nan_under_random_setpoints() -> None:
    rng = random.Random(11)
    plane = _launched()
    for _ in range(30):
        sp: ControlSetpoint
        if rng.random() < 0.5:
            target = [rng.uniform(-500, 500), rng.uniform(-500, 500), rng.uniform(-100, 0)]
            sp = TrajectorySetpoint(position_ned_m=target)
        else:
            sp = RatesSetpoint(
                rates_rad_s=(rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-3, 3)),
                thrust_body=(rng.uniform(0, 1), 0.0, 0.0),
            )
        fly(plane, sp, 1.0, armed=rng.random() > 0.1)
        t = plane.truth
        assert all(math.isfinite(v) for v in (*t.position_ned_m, *t.velocity_ned_m_s, *t.q_wxyz))
        assert t.position_ned_m[2] <= 0.0
