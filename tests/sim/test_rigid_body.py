"""Rigid body and multicopter airframe physics: gravity, ground contact, hover, no NaN."""

from __future__ import annotations

import math
import random

import pytest

from sim.lib.topics import (
    AttitudeSetpoint,
    ControlSetpoint,
    RatesSetpoint,
    TrajectorySetpoint,
    VehicleStateTruth,
)
from sim.models.airframes import AIRFRAME_NAMES, default_params, make_airframe
from sim.models.sim_run import PHYSICS_DT_S, fly
from sim.physics.rigid_body import GRAVITY_M_S2, RigidBody


def _body(truth: VehicleStateTruth, kdv: float = 0.0) -> RigidBody:
    return RigidBody(truth, 1.0, (0.025, 0.025, 0.03), kdv, 0.025)


def test_free_body_falls_at_g() -> None:
    truth = VehicleStateTruth(position_ned_m=[0.0, 0.0, -100.0], on_ground=False)
    body = _body(truth)
    for _ in range(250):
        body.step(PHYSICS_DT_S, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert truth.velocity_ned_m_s[2] == pytest.approx(GRAVITY_M_S2, rel=1e-3)
    assert truth.position_ned_m[2] == pytest.approx(-100.0 + 0.5 * GRAVITY_M_S2, abs=0.03)
    assert truth.acceleration_ned_m_s2[2] == pytest.approx(GRAVITY_M_S2)
    assert not truth.on_ground


def test_drag_limits_fall_speed_to_mass_g_over_kdv() -> None:
    truth = VehicleStateTruth(position_ned_m=[0.0, 0.0, -1000.0], on_ground=False)
    body = _body(truth, kdv=1.0)
    for _ in range(250 * 8):
        body.step(PHYSICS_DT_S, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert truth.velocity_ned_m_s[2] == pytest.approx(GRAVITY_M_S2, rel=0.01)


def test_body_rests_on_the_ground_without_sinking_or_sliding() -> None:
    truth = VehicleStateTruth(position_ned_m=[3.0, 4.0, -2.0], velocity_ned_m_s=[2.0, 0.0, 5.0])
    body = _body(truth)
    for _ in range(500):
        body.step(PHYSICS_DT_S, (0.3, 0.0, 0.0), (0.01, 0.0, 0.0))
    assert truth.position_ned_m[2] == 0.0
    assert truth.velocity_ned_m_s == [0.0, 0.0, 0.0]
    assert truth.rates_body_rad_s == [0.0, 0.0, 0.0]
    assert truth.on_ground
    resting = list(truth.position_ned_m)
    for _ in range(250):
        body.step(PHYSICS_DT_S, (0.3, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert truth.position_ned_m == resting


def test_lift_greater_than_weight_leaves_the_ground() -> None:
    truth = VehicleStateTruth()
    body = _body(truth)
    for _ in range(250):
        body.step(PHYSICS_DT_S, (0.0, 0.0, -1.5 * GRAVITY_M_S2), (0.0, 0.0, 0.0))
    assert not truth.on_ground
    assert truth.position_ned_m[2] < -2.0


def test_infinite_force_resets_to_rest_instead_of_nan() -> None:
    truth = VehicleStateTruth(position_ned_m=[1.0, 2.0, -5.0], on_ground=False)
    body = _body(truth)
    body.step(PHYSICS_DT_S, (math.inf, 0.0, math.nan), (math.nan, 0.0, 0.0))
    state = [*truth.position_ned_m, *truth.velocity_ned_m_s, *truth.q_wxyz, *truth.rates_body_rad_s]
    assert all(math.isfinite(v) for v in state)
    assert truth.position_ned_m[:2] == [1.0, 2.0]


def test_quad_hovers_at_hover_thrust() -> None:
    quad = make_airframe("quad", default_params("quad"))
    quad.reset([0.0, 0.0, -10.0], 0.0)
    hover = 1.0 * GRAVITY_M_S2 / (4 * 5.0)
    fly(quad, RatesSetpoint(thrust_body=(0.0, 0.0, -hover)), 6.0)
    # the motors' spin-up costs a little height; then drag brings the sink to zero and
    # thrust balances weight
    assert quad.truth.velocity_ned_m_s[2] == pytest.approx(0.0, abs=0.01)
    assert quad.truth.acceleration_ned_m_s2[2] == pytest.approx(0.0, abs=0.01)
    assert not quad.truth.on_ground
    assert quad.actuator_outputs == pytest.approx([hover] * 4, abs=1e-3)
    assert quad.power_fraction == pytest.approx(hover, abs=1e-3)


def test_disarmed_quad_in_the_air_falls_and_lands_unharmed() -> None:
    quad = make_airframe("quad", default_params("quad"))
    quad.reset([0.0, 0.0, -20.0], 1.0)
    fly(quad, TrajectorySetpoint(position_ned_m=[0.0, 0.0, -20.0]), 10.0, armed=False)
    assert quad.actuator_outputs == [0.0] * 4
    assert quad.truth.position_ned_m[2] == 0.0
    assert quad.truth.on_ground


def test_motor_outputs_lag_with_sih_time_constant() -> None:
    quad = make_airframe("quad", default_params("quad"))
    quad.reset([0.0, 0.0, 0.0], 0.0)
    fly(quad, RatesSetpoint(thrust_body=(0.0, 0.0, -0.8)), 0.05)
    # one time constant (SIH_T_TAU 0.05 s) reaches ≈ 63 % of the step
    assert quad.power_fraction == pytest.approx(0.8 * (1 - math.exp(-1)), abs=0.03)


@pytest.mark.parametrize("airframe", ["quad", "hexa", "octo"])
def test_multicopter_never_produces_nan_under_random_setpoints(airframe: str) -> None:
    rng = random.Random(7)
    model = make_airframe(airframe, default_params(airframe))
    model.reset([0.0, 0.0, 0.0], 0.0)
    for _ in range(40):
        kind = rng.randrange(4)
        sp: ControlSetpoint
        if kind == 0:
            sp = TrajectorySetpoint(
                position_ned_m=[rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(-30, 5)],
                yaw_rad=rng.choice([math.nan, rng.uniform(-4, 4)]),
            )
        elif kind == 1:
            sp = TrajectorySetpoint(
                velocity_ned_m_s=[rng.uniform(-15, 15), rng.uniform(-15, 15), rng.uniform(-5, 5)],
                yawspeed_rad_s=rng.uniform(-3, 3),
            )
        elif kind == 2:
            sp = TrajectorySetpoint(
                acceleration_ned_m_s2=[rng.uniform(-9, 9), rng.uniform(-9, 9), rng.uniform(-9, 9)]
            )
        else:
            sp = RatesSetpoint(
                rates_rad_s=(rng.uniform(-6, 6), rng.uniform(-6, 6), rng.uniform(-6, 6)),
                thrust_body=(0.0, 0.0, -rng.uniform(0, 1)),
            )
        fly(model, sp, 0.5, armed=rng.random() > 0.1)
        t = model.truth
        state = [*t.position_ned_m, *t.velocity_ned_m_s, *t.acceleration_ned_m_s2, *t.q_wxyz]
        assert all(math.isfinite(v) for v in state)
        assert t.position_ned_m[2] <= 0.0
        assert all(0.0 <= u <= 1.0 for u in model.actuator_outputs)


@pytest.mark.parametrize("airframe", AIRFRAME_NAMES)
def test_nan_attitude_and_rates_setpoints_do_not_poison_the_model(airframe: str) -> None:
    model = make_airframe(airframe, default_params(airframe))
    model.reset([0.0, 0.0, -30.0 if airframe != "rover" else 0.0], 0.5)
    if airframe in ("plane",):
        model.truth.velocity_ned_m_s[0] = 15.0
    nan = math.nan
    fly(model, RatesSetpoint(rates_rad_s=(nan, 0.2, nan), thrust_body=(nan, 0.0, -0.5)), 0.5)
    fly(model, AttitudeSetpoint(q_wxyz=(nan, 0.0, 0.0, 0.0), thrust_body=(0.5, 0.0, nan)), 0.5)
    fly(model, AttitudeSetpoint(q_wxyz=(0.0, 0.0, 0.0, 0.0), thrust_body=(0.5, 0.0, -0.5)), 0.5)
    target = [0.0, 0.0, -30.0] if airframe != "rover" else [5.0, 0.0, 0.0]
    fly(model, TrajectorySetpoint(position_ned_m=target), 15.0)
    t = model.truth
    state = [*t.position_ned_m, *t.velocity_ned_m_s, *t.acceleration_ned_m_s2, *t.q_wxyz]
    assert all(math.isfinite(v) for v in state)
    assert all(math.isfinite(u) for u in model.actuator_outputs)
    if airframe in ("quad", "hexa", "octo", "rover"):
        # still controllable afterwards
        assert math.dist(t.position_ned_m, target) < 1.0
