"""RTL of the winged airframes on their real flight models: the plane loiters down over
home and lands on its loiter circle; the VTOL flies an approach, transitions back to
multicopter and lands at home. Both end landed and disarmed after COM_DISARM_LAND."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.flight.navigator import RtlPhase
from sim.lib.topics import VtolState
from sim.vehicle import SimVehicle
from tests.sim.conftest import Harness, HarnessFactory

NAN6 = [math.nan] * 6


def winged(airframe: str) -> Harness:
    h = Harness(SimVehicle(airframe))
    h.wait_ready()
    return h


def take_off(h: Harness) -> None:
    h.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *NAN6, math.nan)
    h.arm()
    h.run_until(lambda: h.vehicle.mode_name == "AUTO_LOITER", 90.0)


def home_distance_m(h: Harness) -> float:
    north, east, _ = h.vehicle.truth.position_ned_m
    home = h.vehicle.commander.home.position_ned_m
    return math.hypot(north - home[0], east - home[1])


def return_and_disarm(h: Harness) -> tuple[float, float]:
    """RTL until disarmed; the sim times of touchdown (landed) and of the disarm."""
    v = h.vehicle
    h.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    h.run_until(lambda: v.commander.landed, 240.0)
    landed_s = v.now_s
    h.run_until(lambda: not v.armed, 30.0)
    return landed_s, v.now_s


def test_plane_rtl_loiters_forever_with_px4_sitls_rtl_land_delay() -> None:
    h = winged("plane")
    assert h.vehicle.params.get("RTL_LAND_DELAY") == -1.0  # rc.fw_defaults
    take_off(h)
    h.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    h.run_until(lambda: h.vehicle.navigator.rtl_phase == RtlPhase.LOITER_HOLD, 240.0)
    h.run(30.0)
    assert h.vehicle.navigator.rtl_phase == RtlPhase.LOITER_HOLD
    assert h.vehicle.armed


def test_plane_rtl_loiters_down_then_lands_on_its_circle_and_disarms() -> None:
    h = winged("plane")
    h.vehicle.params.set("RTL_LAND_DELAY", 0.0)
    take_off(h)
    landed_s, disarmed_s = return_and_disarm(h)
    assert h.vehicle.rtl_phases == [
        RtlPhase.CLIMBING, RtlPhase.MOVE_TO_LOITER, RtlPhase.LOITER_DOWN,
        RtlPhase.LOITER_HOLD, RtlPhase.MOVE_TO_LAND_HOVER, RtlPhase.LAND, RtlPhase.IDLE,
    ]
    texts = [t for t in h.api.texts() if t.startswith("RTL")]
    assert texts[-1] == "RTL: land at destination"
    assert disarmed_s - landed_s == pytest.approx(
        h.vehicle.params.get("COM_DISARM_LAND"), abs=0.05)
    truth = h.vehicle.truth
    assert truth.on_ground
    assert truth.position_ned_m[2] == pytest.approx(0.0, abs=0.05)
    assert home_distance_m(h) <= 1.5 * h.vehicle.params.get("NAV_LOITER_RAD")


def test_plane_rtl_descends_to_rtl_descend_alt_and_holds_rtl_land_delay() -> None:
    h = winged("plane")
    v = h.vehicle
    v.params.set("RTL_DESCEND_ALT", 40.0)
    v.params.set("RTL_LAND_DELAY", 4.0)
    take_off(h)
    h.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    h.run_until(lambda: v.navigator.rtl_phase == RtlPhase.LOITER_HOLD, 120.0)
    assert -v.truth.position_ned_m[2] == pytest.approx(40.0, abs=1.0)
    held_s = h.run_until(lambda: v.navigator.rtl_phase != RtlPhase.LOITER_HOLD, 10.0)
    assert held_s == pytest.approx(4.0, abs=0.05)


def test_plane_rtl_with_negative_land_delay_loiters_and_never_lands(
    make_harness: HarnessFactory,
) -> None:
    h = make_harness("plane")
    v = h.vehicle
    v.params.set("RTL_LAND_DELAY", -1.0)
    take_off(h)
    h.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    h.run_until(lambda: v.navigator.rtl_phase == RtlPhase.LOITER_HOLD, 120.0)
    h.run(30.0)
    assert v.navigator.rtl_phase == RtlPhase.LOITER_HOLD
    assert v.armed
    assert not v.commander.landed


def test_vtol_rtl_approaches_transitions_to_multicopter_and_lands_at_home() -> None:
    h = winged("vtol")
    v = h.vehicle
    take_off(h)
    h.command_long(mavlink.MAV_CMD_DO_VTOL_TRANSITION, mavlink.MAV_VTOL_STATE_FW)
    h.run_until(lambda: v.vtol_state == VtolState.FW, 30.0)
    h.run(10.0)  # out on its loiter circle, in fixed-wing flight
    landed_s, disarmed_s = return_and_disarm(h)
    assert v.rtl_phases == [
        RtlPhase.CLIMBING, RtlPhase.MOVE_TO_LOITER, RtlPhase.LOITER_DOWN,
        RtlPhase.LOITER_HOLD, RtlPhase.MOVE_TO_LAND, RtlPhase.TRANSITION_TO_MC,
        RtlPhase.MOVE_TO_LAND_HOVER, RtlPhase.LAND, RtlPhase.IDLE,
    ]
    assert v.vtol_state == VtolState.MC
    assert disarmed_s - landed_s == pytest.approx(v.params.get("COM_DISARM_LAND"), abs=0.05)
    assert home_distance_m(h) < 1.0
