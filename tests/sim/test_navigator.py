"""Navigator: takeoff, land, hold, reposition and the RTL phases with their STATUSTEXTs."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.flight.navigator import RtlPhase
from sim.lib import modes
from tests.sim.conftest import Harness, HarnessFactory

NAN7 = [math.nan] * 7


def take_off(h: Harness, alt_amsl_m: float = math.nan) -> None:
    h.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *NAN7[:6], alt_amsl_m)
    h.arm()
    h.run_until(lambda: h.vehicle.mode_name == "AUTO_LOITER", 60.0)


def altitude_m(h: Harness) -> float:
    return -h.vehicle.truth.position_ned_m[2]


def test_takeoff_climbs_to_mis_takeoff_alt_and_switches_to_hold_near_it(harness: Harness) -> None:
    take_off(harness)
    assert 0.85 * 2.5 <= altitude_m(harness) <= 2.5
    harness.run(3.0)
    assert altitude_m(harness) == pytest.approx(2.5, abs=0.1)
    assert harness.vehicle.commander.user_mode.name == "AUTO_LOITER"


def test_takeoff_altitude_parameter_change_takes_effect(harness: Harness) -> None:
    harness.vehicle.params.set("MIS_TAKEOFF_ALT", 6.0)
    take_off(harness)
    harness.run(3.0)
    assert altitude_m(harness) == pytest.approx(6.0, abs=0.1)


def test_takeoff_param7_is_amsl(harness: Harness) -> None:
    take_off(harness, harness.vehicle.origin.alt_m + 8.0)
    harness.run(3.0)
    assert altitude_m(harness) == pytest.approx(8.0, abs=0.1)


def test_land_descends_at_land_speed_below_alt2_then_disarms(harness: Harness) -> None:
    take_off(harness)
    harness.command_long(mavlink.MAV_CMD_NAV_LAND)
    harness.run(1.5)
    assert harness.vehicle.truth.velocity_ned_m_s[2] == pytest.approx(0.7, abs=0.05)
    harness.run_until(lambda: not harness.vehicle.armed, 15.0)
    # UserModeIntention::onDisarm: Land keeps a vehicle from arming, so once disarmed PX4
    # goes back to the mode chosen before it (Hold, after the takeoff)
    assert harness.vehicle.mode_name == "AUTO_LOITER"


def test_land_speed_profile_between_land_altitudes(harness: Harness) -> None:
    nav = harness.vehicle.navigator
    assert nav.land_speed_m_s(20.0) == 1.5
    assert nav.land_speed_m_s(7.5) == pytest.approx((1.5 + 0.7) / 2)
    assert nav.land_speed_m_s(2.0) == 0.7
    # below MPC_LAND_ALT3 (the range finder reads it) PX4 crawls at MPC_LAND_CRWL
    assert nav.land_speed_m_s(0.8) == 0.3


def test_hold_keeps_position(harness: Harness) -> None:
    take_off(harness)
    before = list(harness.vehicle.truth.position_ned_m)
    harness.run(5.0)
    assert harness.vehicle.truth.position_ned_m == pytest.approx(before, abs=0.3)


def test_reposition_flies_there_in_hold(harness: Harness) -> None:
    take_off(harness)
    v = harness.vehicle
    alt_at_command_m = altitude_m(harness)  # NaN altitude: keep the current one
    target = v.origin.to_geodetic(15.0, 0.0, 0.0)
    harness.command_int(mavlink.MAV_CMD_DO_REPOSITION, mavlink.MAV_FRAME_GLOBAL_INT,
                        (-1, 1, 0, math.nan), round(target.lat_deg * 1e7),
                        round(target.lon_deg * 1e7), math.nan)
    harness.run(15.0)
    assert v.truth.position_ned_m[0] == pytest.approx(15.0, abs=0.2)
    assert altitude_m(harness) == pytest.approx(alt_at_command_m, abs=0.05)


def rtl_from(h: Harness, north_m: float, alt_m: float) -> None:
    h.vehicle.params.set("MIS_TAKEOFF_ALT", alt_m)
    take_off(h)
    target = h.vehicle.origin.to_geodetic(north_m, 0.0, 0.0)
    h.command_long(mavlink.MAV_CMD_DO_REPOSITION, -1, 1, 0, math.nan, target.lat_deg,
                   target.lon_deg, math.nan)
    h.run_until(lambda: abs(h.vehicle.truth.position_ned_m[0] - north_m) < 0.5, 60.0)
    h.api.clear()
    h.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)


def test_rtl_phases_in_rtl_direct_order_with_statustext_and_disarm(harness: Harness) -> None:
    rtl_from(harness, 15.0, 10.0)
    harness.run_until(lambda: not harness.vehicle.armed, 120.0)
    assert harness.vehicle.rtl_phases == [
        RtlPhase.CLIMBING, RtlPhase.MOVE_TO_LOITER, RtlPhase.LOITER_DOWN,
        RtlPhase.LOITER_HOLD, RtlPhase.MOVE_TO_LAND_HOVER, RtlPhase.LAND, RtlPhase.IDLE,
    ]
    # SIH_LOC_H0 489.4 m + RTL_RETURN_ALT 30 m, rounded up as PX4 does
    texts = [t for t in harness.api.texts() if t.startswith("RTL")]
    assert texts == ["RTL: start return at 520 m (30 m above destination)",
                     "RTL: land at destination"]
    assert "Returning to launch" in harness.api.texts()
    assert "Disarmed by landing" in harness.api.texts()
    # once disarmed PX4 reports the mode chosen before RTL (Hold, after the takeoff)
    assert harness.vehicle.mode_name == "AUTO_LOITER"
    north, east, _ = harness.vehicle.truth.position_ned_m
    assert math.hypot(north, east) < 1.0


def test_rtl_descends_to_rtl_descend_alt_and_loiters_rtl_land_delay(harness: Harness) -> None:
    params = harness.vehicle.params
    params.set("RTL_DESCEND_ALT", 12.0)
    params.set("RTL_LAND_DELAY", 3.0)
    rtl_from(harness, 15.0, 10.0)
    harness.run_until(lambda: harness.vehicle.navigator.rtl_phase == RtlPhase.LOITER_HOLD, 60.0)
    assert altitude_m(harness) == pytest.approx(12.0, abs=0.6)
    took = harness.run_until(
        lambda: harness.vehicle.navigator.rtl_phase != RtlPhase.LOITER_HOLD, 10.0)
    assert took == pytest.approx(3.0, abs=0.05)


def test_rtl_near_home_does_not_climb(harness: Harness) -> None:
    rtl_from(harness, 5.0, 4.0)  # inside RTL_MIN_DIST
    harness.run(0.1)
    assert RtlPhase.CLIMBING not in harness.vehicle.rtl_phases
    assert harness.vehicle.rtl_phases[0] == RtlPhase.MOVE_TO_LOITER


def test_rtl_above_return_altitude_returns_at_current_altitude(harness: Harness) -> None:
    harness.vehicle.params.set("RTL_RETURN_ALT", 5.0)
    rtl_from(harness, 20.0, 10.0)
    start_alt_m = altitude_m(harness)
    harness.run_until(lambda: RtlPhase.LOITER_DOWN in harness.vehicle.rtl_phases, 60.0)
    assert RtlPhase.CLIMBING not in harness.vehicle.rtl_phases
    assert altitude_m(harness) == pytest.approx(start_alt_m, abs=0.3)


def test_rtl_when_landed_is_idle(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    harness.run(0.1)
    assert harness.vehicle.rtl_phases == [RtlPhase.IDLE]


def test_vtol_in_fixed_wing_transitions_back_before_landing(make_harness: HarnessFactory) -> None:
    h = make_harness("vtol")
    h.vehicle.params.set("MIS_TAKEOFF_ALT", 5.0)
    take_off(h)
    h.command_long(mavlink.MAV_CMD_DO_VTOL_TRANSITION, 4)
    h.command_long(mavlink.MAV_CMD_NAV_LAND)
    h.run(0.1)
    assert h.model.transitions[-1] == (False, False)


def test_rover_returns_home_on_the_ground_and_stays_armed(make_harness: HarnessFactory) -> None:
    h = make_harness("rover")
    v = h.vehicle
    h.arm()
    h.run(0.1)
    assert not v.commander.landed  # PX4's rover land detector: landed only while disarmed
    target = v.origin.to_geodetic(20.0, 0.0, 0.0)
    h.command_long(mavlink.MAV_CMD_DO_REPOSITION, -1, 1, 0, math.nan, target.lat_deg,
                   target.lon_deg, math.nan)
    h.run_until(lambda: abs(v.truth.position_ned_m[0] - 20.0) < 0.5, 30.0)
    h.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    h.run_until(lambda: RtlPhase.IDLE in v.rtl_phases, 60.0)
    assert RtlPhase.CLIMBING not in v.rtl_phases
    assert math.hypot(*v.truth.position_ned_m[:2]) < 1.0
    assert v.truth.position_ned_m[2] == 0.0
    h.run(12.0)
    assert v.armed  # no auto-disarm for an armed rover


def test_second_takeoff_by_mode_change_climbs_from_where_it_is(harness: Harness) -> None:
    take_off(harness)
    harness.command_long(mavlink.MAV_CMD_NAV_LAND)
    harness.run_until(lambda: not harness.vehicle.armed, 30.0)
    harness.vehicle.params.set("MIS_TAKEOFF_ALT", 4.0)
    harness.set_mode(modes.AUTO_TAKEOFF)  # disarmed: the target is not fixed yet
    harness.arm()
    harness.run_until(lambda: harness.vehicle.mode_name == "AUTO_LOITER", 30.0)
    harness.run(3.0)
    assert altitude_m(harness) == pytest.approx(4.0, abs=0.1)
