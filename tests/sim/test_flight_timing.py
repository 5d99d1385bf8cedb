"""Flight phases on PX4's clock, flown by the real SIH quad in sim time: the takeoff's
spool-up and ramp (COM_SPOOLUP_TIME, MPC_TKO_RAMP_T, MPC_TKO_SPEED), the landing descent by
altitude (MPC_LAND_SPEED, MPC_LAND_ALT1/2/3, MPC_LAND_CRWL) and the land detector's stages
(LNDMC_TRIG_TIME), home at the first HEARTBEAT. The whole table against real PX4 SITL is
bench/parity_timing.py."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.control.mc_takeoff import TakeoffState
from sim.lib.topics import LandingStatus
from sim.vehicle import BOOT_TIME_S, PHYSICS_DT_S, SimVehicle
from tests.sim.conftest import Harness

NAN6 = [math.nan] * 6


@pytest.fixture
def quad() -> Harness:
    harness = Harness(SimVehicle("quad"))
    harness.wait_ready()
    return harness


def landing_status(h: Harness) -> LandingStatus:
    landing = h.vehicle.model.landing
    assert landing is not None
    return landing


def height_m(h: Harness) -> float:
    return -h.vehicle.truth.position_ned_m[2]


def climb_rate_m_s(h: Harness) -> float:
    return -h.vehicle.truth.velocity_ned_m_s[2]


def take_off(h: Harness, height: float) -> float:
    """Arm, NAV_TAKEOFF to `height` above home; the sim time until Takeoff hands over."""
    h.arm()
    h.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *NAN6, h.vehicle.origin.alt_m + height)
    return h.run_until(lambda: h.vehicle.mode_name == "AUTO_LOITER", 60.0)


def test_home_is_set_as_the_first_heartbeat_goes_out() -> None:
    vehicle = SimVehicle("quad")
    while not vehicle.booted:
        assert not vehicle.commander.home.valid
        vehicle.step(PHYSICS_DT_S)
    assert vehicle.commander.home.valid
    assert vehicle.now_s == pytest.approx(BOOT_TIME_S, abs=PHYSICS_DT_S)
    assert not vehicle.ready  # arming waits for the rest of the checks


def test_takeoff_spools_up_then_ramps_to_mpc_tko_speed(quad: Harness) -> None:
    quad.arm()
    quad.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *NAN6, quad.vehicle.origin.alt_m + 10.0)
    control = landing_status(quad)
    quad.run(0.9)  # COM_SPOOLUP_TIME 1 s: no thrust yet
    assert control.takeoff_state == TakeoffState.SPOOLUP
    assert height_m(quad) < 0.01
    # the ramp starts from -g / MPC_Z_VEL_P_ACC and needs ~1.9 s of its 3 s to ask for a climb
    quad.run(1.9)
    assert control.takeoff_state == TakeoffState.RAMPUP
    assert height_m(quad) < 0.05
    lifted = quad.run_until(lambda: height_m(quad) > 1.0, 10.0) + 2.8
    assert 4.0 <= lifted <= 6.0  # PX4 v1.16 SITL: 5.5 s after NAV_TAKEOFF
    quad.run(1.0)
    assert control.takeoff_state == TakeoffState.FLIGHT
    # the integrator still holds some of the ramp (PX4 climbs 1 → 4 m in 2.6 s), then
    quad.run(3.0)
    assert climb_rate_m_s(quad) == pytest.approx(1.5, abs=0.1)


def test_takeoff_ramp_time_and_speed_are_parameters(quad: Harness) -> None:
    quad.vehicle.params.set("MPC_TKO_RAMP_T", 0.5)
    quad.vehicle.params.set("COM_SPOOLUP_TIME", 0.2)
    quad.vehicle.params.set("MPC_TKO_SPEED", 2.5)
    quad.run(0.3)  # the controllers read their parameters within 0.2 s
    quad.arm()
    quad.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *NAN6, quad.vehicle.origin.alt_m + 10.0)
    assert quad.run_until(lambda: height_m(quad) > 1.0, 10.0) < 2.5
    quad.run(1.0)
    assert climb_rate_m_s(quad) == pytest.approx(2.5, abs=0.25)


def test_takeoff_hands_over_at_the_target_height(quad: Harness) -> None:
    took = take_off(quad, 5.0)
    assert 4.85 <= height_m(quad) <= 5.05
    assert 7.5 <= took <= 11.0  # PX4 v1.16 SITL: 9.3 s
    assert quad.vehicle.landed_state != 1


def land_from_5_m(h: Harness) -> tuple[float, float]:
    """NAV_LAND from a 5 m hover: (sim time to touchdown, to ON_GROUND)."""
    take_off(h, 5.0)
    h.run(3.0)
    h.command_long(mavlink.MAV_CMD_NAV_LAND)
    start = h.vehicle.now_s
    h.run_until(lambda: h.vehicle.truth.on_ground, 60.0)
    touchdown = h.vehicle.now_s - start
    h.run_until(lambda: h.vehicle.commander.landed, 30.0)
    return touchdown, h.vehicle.now_s - start


def test_landing_descends_by_altitude_then_crawls_and_detects_in_stages(quad: Harness) -> None:
    take_off(quad, 5.0)
    quad.run(3.0)
    quad.command_long(mavlink.MAV_CMD_NAV_LAND)
    quad.run_until(lambda: height_m(quad) < 3.0, 20.0)
    assert -climb_rate_m_s(quad) == pytest.approx(0.7, abs=0.05)  # MPC_LAND_SPEED below ALT2
    quad.run_until(lambda: height_m(quad) < 0.6, 20.0)
    assert -climb_rate_m_s(quad) == pytest.approx(0.3, abs=0.05)  # MPC_LAND_CRWL below ALT3
    quad.run_until(lambda: quad.vehicle.truth.on_ground, 10.0)
    assert not quad.vehicle.commander.landed
    landing = landing_status(quad)
    # the thrust winds down until ground contact, which cuts it; then maybe landed, landed
    contact = quad.run_until(lambda: landing.ground_contact, 10.0)
    assert contact > 0.5
    assert not landing.landed
    detected = quad.run_until(lambda: landing.landed, 5.0)
    assert detected == pytest.approx(2 / 3, abs=0.1)  # two more LNDMC_TRIG_TIME / 3 stages
    took = quad.run_until(lambda: not quad.vehicle.armed, 5.0)
    assert took == pytest.approx(2.0, abs=0.05)  # COM_DISARM_LAND


def test_a_higher_mpc_land_speed_lands_faster(make_quad_pair: tuple[Harness, Harness]) -> None:
    default, faster = make_quad_pair
    faster.vehicle.params.set("MPC_LAND_SPEED", 1.4)
    _, default_s = land_from_5_m(default)
    _, faster_s = land_from_5_m(faster)
    # 4 m at 1.4 instead of 0.7 m/s: 2.9 s less, and a faster touchdown (a larger
    # integrator to unwind) is not detected later
    assert default_s - faster_s >= 2.5


def test_a_longer_lndmc_trig_time_detects_the_landing_later(
    make_quad_pair: tuple[Harness, Harness],
) -> None:
    default, slower = make_quad_pair
    slower.vehicle.params.set("LNDMC_TRIG_TIME", 3.0)
    touchdown_a, landed_a = land_from_5_m(default)
    touchdown_b, landed_b = land_from_5_m(slower)
    assert (landed_b - touchdown_b) - (landed_a - touchdown_a) == pytest.approx(2.0, abs=0.3)


@pytest.fixture
def make_quad_pair() -> tuple[Harness, Harness]:
    pair = (Harness(SimVehicle("quad")), Harness(SimVehicle("quad")))
    for harness in pair:
        harness.wait_ready()
    return pair
