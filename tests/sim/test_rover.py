"""Differential rover: drives to a point and stops, tracks velocity, respects its limits."""

from __future__ import annotations

import math
import random

import pytest

from sim.lib.quat import yaw_from_quat
from sim.lib.topics import ControlSetpoint, RatesSetpoint, TrajectorySetpoint, VtolState
from sim.models.airframes import AirframeModel, default_params, make_airframe
from sim.models.sim_run import fly, fly_peak


def _rover(yaw_rad: float = 0.0) -> AirframeModel:
    rover = make_airframe("rover", default_params("rover"))
    rover.reset([0.0, 0.0, 0.0], yaw_rad)
    return rover


def _speed(rover: AirframeModel) -> float:
    return math.hypot(*rover.truth.velocity_ned_m_s[:2])


def test_rover_identity() -> None:
    rover = _rover()
    assert rover.mav_type == 10
    assert not rover.is_vtol
    assert rover.vtol_state == VtolState.UNDEFINED
    assert rover.truth.on_ground


def test_rover_drives_to_a_point_behind_it_and_stops() -> None:
    rover = _rover(yaw_rad=0.0)
    target = [-10.0, 20.0, 0.0]
    sp = TrajectorySetpoint(position_ned_m=target)
    fastest = fly_peak(rover, sp, 15.0, lambda: _speed(rover))
    assert math.dist(rover.truth.position_ned_m, target) < 0.3
    assert _speed(rover) == 0.0
    # cruises at GND_SPEED_TRIM on the way
    assert fastest == pytest.approx(3.0, abs=0.05)
    parked = list(rover.truth.position_ned_m)
    fly(rover, sp, 3.0)
    assert rover.truth.position_ned_m == parked
    assert rover.truth.position_ned_m[2] == 0.0


def test_rover_turns_to_the_setpoint_yaw_once_arrived() -> None:
    rover = _rover()
    sp = TrajectorySetpoint(position_ned_m=[5.0, 0.0, 0.0], yaw_rad=math.radians(-90.0))
    fly(rover, sp, 10.0)
    assert math.degrees(yaw_from_quat(rover.truth.q_wxyz)) == pytest.approx(-90.0, abs=2.0)
    assert math.dist(rover.truth.position_ned_m, [5.0, 0.0, 0.0]) < 0.3


def test_rover_tracks_a_velocity_setpoint_capped_at_gnd_speed_max() -> None:
    params = default_params("rover")
    params.values["GND_SPEED_MAX"] = 4.0
    rover = make_airframe("rover", params)
    rover.reset([0.0, 0.0, 0.0], 0.0)
    fly(rover, TrajectorySetpoint(velocity_ned_m_s=[0.0, 2.0, 0.0]), 5.0)
    v = rover.truth.velocity_ned_m_s
    assert v[0] == pytest.approx(0.0, abs=0.05)
    assert v[1] == pytest.approx(2.0, abs=0.05)
    fly(rover, TrajectorySetpoint(velocity_ned_m_s=[9.0, 0.0, 0.0]), 8.0)
    assert _speed(rover) == pytest.approx(4.0, abs=0.01)
    assert rover.actuator_outputs == pytest.approx([1.0, 1.0], abs=0.01)


def test_rover_accelerates_within_ro_accel_lim() -> None:
    rover = _rover()
    fly(rover, TrajectorySetpoint(velocity_ned_m_s=[6.0, 0.0, 0.0]), 1.0)
    assert _speed(rover) == pytest.approx(2.0, abs=0.05)


def test_disarmed_rover_brakes_to_a_stop() -> None:
    rover = _rover()
    sp = TrajectorySetpoint(velocity_ned_m_s=[3.0, 0.0, 0.0])
    fly(rover, sp, 3.0)
    fly(rover, sp, 1.5, armed=False)
    assert _speed(rover) == 0.0


def test_rates_setpoint_spins_the_rover_in_place() -> None:
    rover = _rover()
    fly(rover, RatesSetpoint(rates_rad_s=(0.0, 0.0, 1.0), thrust_body=(0.0, 0.0, 0.0)), 1.0)
    assert rover.truth.rates_body_rad_s[2] == pytest.approx(1.0, abs=0.01)
    left, right = rover.actuator_outputs
    assert left < 0.0 < right
    assert rover.truth.position_ned_m == [0.0, 0.0, 0.0]


def test_rover_never_produces_nan_under_random_setpoints() -> None:
    rng = random.Random(5)
    rover = _rover()
    for _ in range(40):
        sp: ControlSetpoint = TrajectorySetpoint(
            position_ned_m=[rng.uniform(-30, 30), rng.uniform(-30, 30), math.nan],
            velocity_ned_m_s=[rng.uniform(-20, 20), rng.uniform(-20, 20), 0.0],
            yaw_rad=rng.choice([math.nan, rng.uniform(-4, 4)]),
        )
        if rng.random() < 0.3:
            sp = TrajectorySetpoint(velocity_ned_m_s=[rng.uniform(-20, 20), math.nan, 0.0])
        fly(rover, sp, 0.5, armed=rng.random() > 0.1)
        t = rover.truth
        assert all(math.isfinite(v) for v in (*t.position_ned_m, *t.velocity_ned_m_s, *t.q_wxyz))
        assert all(-1.0 <= u <= 1.0 for u in rover.actuator_outputs)
