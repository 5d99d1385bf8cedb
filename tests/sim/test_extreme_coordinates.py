"""Legal but extreme origins and homes: the vehicle keeps flying and every frame it sends is
in range (poles, the antimeridian, a home on the other side of the globe, huge altitudes)."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.lib.geo import LocalOrigin
from sim.vehicle import SimVehicle
from tests.sim.conftest import Harness, HarnessFactory

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
DENIED = mavlink.MAV_RESULT_DENIED
SET_HOME = mavlink.MAV_CMD_DO_SET_HOME
# GLOBAL_POSITION_INT, GPS_RAW_INT and HOME_POSITION carry lat/lon in degE7
LAT_LIMIT_E7 = 900_000_000
LON_LIMIT_E7 = 1_800_000_000


def set_origin(harness: Harness, lat_deg: float, lon_deg: float, alt_m: float) -> None:
    harness.deliver(mavlink.MAVLink_set_gps_global_origin_message(
        1, round(lat_deg * 1e7), round(lon_deg * 1e7), round(alt_m * 1000.0)))


def assert_positions_on_the_globe(harness: Harness) -> None:
    """Every position the vehicle reported is a finite point within the globe's ranges."""
    geodetic = [
        (m.lat, m.lon) for m in harness.api.of_type("GLOBAL_POSITION_INT")
    ] + [
        (m.lat, m.lon) for m in harness.api.of_type("GPS_RAW_INT") if m.fix_type >= 3
    ] + [
        (m.latitude, m.longitude) for m in harness.api.of_type("HOME_POSITION")
    ]
    assert geodetic, "no position reported"
    for lat_e7, lon_e7 in geodetic:
        assert abs(lat_e7) <= LAT_LIMIT_E7
        assert abs(lon_e7) <= LON_LIMIT_E7
    for m in harness.api.of_type("LOCAL_POSITION_NED"):
        assert all(math.isfinite(x) for x in (m.x, m.y, m.z, m.vx, m.vy, m.vz))


@pytest.mark.parametrize(
    ("lat_deg", "lon_deg", "alt_m"),
    [
        (90.0, 0.0, 489.4),  # north pole
        (-90.0, -180.0, 489.4),  # south pole on the antimeridian
        (0.0, 180.0, 0.0),  # the antimeridian from the east
        (0.0, -180.0, 0.0),  # and from the west
        (89.9999999, 179.9999999, 1.0e5),  # next to the pole, huge altitude
        (-45.0, 120.0, -1.0e3),  # below sea level
        (47.4, 8.5, 2_000_000.0),  # the largest altitudes the message carries
        (47.4, 8.5, -2_000_000.0),
    ],
)
def test_extreme_origin_is_accepted_and_telemetry_stays_in_range(
    harness: Harness, lat_deg: float, lon_deg: float, alt_m: float,
) -> None:
    set_origin(harness, lat_deg, lon_deg, alt_m)
    (origin,) = harness.api.of_type("GPS_GLOBAL_ORIGIN")
    assert origin.latitude == round(lat_deg * 1e7)
    assert origin.longitude == round(lon_deg * 1e7)
    harness.api.clear()
    harness.run(1.5)
    assert_positions_on_the_globe(harness)


def test_vehicle_flies_on_after_the_origin_moves_to_a_pole(harness: Harness) -> None:
    set_origin(harness, 90.0, 180.0, 489.4)
    harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    harness.arm()
    harness.run_until(lambda: harness.vehicle.mode_name == "AUTO_LOITER", timeout_s=30.0)
    harness.api.clear()
    harness.run(1.0)
    assert_positions_on_the_globe(harness)
    assert harness.api.of_type("HEARTBEAT")


@pytest.mark.parametrize(
    ("lat_deg", "lon_deg", "alt_m"),
    [
        (-47.397742, -171.454406, 489.4),  # the antipode of the default origin
        (-90.0, 180.0, 1.0e5),
        (90.0, -180.0, -1.0e3),
        (0.0, 0.0, 2_000_000.0),
    ],
)
def test_far_away_home_is_set_and_reported_in_range(
    harness: Harness, lat_deg: float, lon_deg: float, alt_m: float,
) -> None:
    harness.api.clear()  # the HOME_POSITION streamed since the boot
    harness.command_long(SET_HOME, 0, 0, 0, 90.0, lat_deg, lon_deg, alt_m)
    assert harness.last_ack(SET_HOME) == ACCEPTED
    home = harness.vehicle.commander.home
    # COMMAND_LONG carries float32 params
    assert [home.lat_deg, home.lon_deg] == pytest.approx([lat_deg, lon_deg], abs=1e-5)
    assert home.alt_m == pytest.approx(alt_m, rel=1e-6)
    assert home.yaw_rad == pytest.approx(math.radians(90.0))
    assert all(math.isfinite(x) for x in home.position_ned_m)
    (reported,) = harness.api.of_type("HOME_POSITION")
    assert reported.latitude == pytest.approx(lat_deg * 1e7, abs=100)
    harness.run(1.5)
    assert_positions_on_the_globe(harness)


@pytest.mark.parametrize(
    ("lat_deg", "lon_deg", "alt_m"),
    [(90.5, 0.0, 0.0), (0.0, -180.5, 0.0), (0.0, 0.0, 1.0e30), (-91.0, 200.0, -1.0e9)],
)
def test_home_off_the_globe_is_denied_with_a_reason(
    harness: Harness, lat_deg: float, lon_deg: float, alt_m: float,
) -> None:
    before = list(harness.vehicle.commander.home.position_ned_m)
    harness.command_long(SET_HOME, 0, 0, 0, 0, lat_deg, lon_deg, alt_m)
    assert harness.last_ack(SET_HOME) == DENIED
    assert any(text.startswith("Home not set") for text in harness.api.texts())
    assert harness.vehicle.commander.home.position_ned_m == before


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_home_with_non_finite_coordinates_is_denied(harness: Harness, bad: float) -> None:
    for lat, lon, alt in ((bad, 8.5, 400.0), (47.0, bad, 400.0), (47.0, 8.5, bad)):
        harness.command_long(SET_HOME, 0, 0, 0, 0, lat, lon, alt)
        assert harness.last_ack(SET_HOME) == DENIED


def test_origin_off_the_globe_is_refused_and_the_old_origin_reported(
    harness: Harness,
) -> None:
    before = harness.vehicle.origin
    set_origin(harness, 95.0, 200.0, 400.0)
    assert harness.vehicle.origin is before
    (origin,) = harness.api.of_type("GPS_GLOBAL_ORIGIN")
    assert origin.latitude == round(before.lat_deg * 1e7)
    assert origin.longitude == round(before.lon_deg * 1e7)
    assert any(text.startswith("Failed to set new NED origin") for text in harness.api.texts())


@pytest.mark.parametrize("origin_lat_deg", [90.0, -90.0, 89.95])
def test_conversion_next_to_a_pole_is_finite_and_round_trips(origin_lat_deg: float) -> None:
    origin = LocalOrigin(origin_lat_deg, 180.0, 100.0)
    for ned in ((0.0, 0.0, 0.0), (10.0, 10.0, -5.0), (-300.0, 120.0, -50.0), (0.0, 0.0, 1e6)):
        point = origin.to_geodetic(*ned)
        assert -90.0 <= point.lat_deg <= 90.0
        assert -180.0 <= point.lon_deg < 180.0
        assert math.isfinite(point.alt_m)
        back = origin.to_ned(point.lat_deg, point.lon_deg, point.alt_m)
        assert back == pytest.approx(list(ned), abs=0.05)


def test_positions_past_the_antimeridian_wrap_longitude() -> None:
    origin = LocalOrigin(0.0, 179.9999, 0.0)
    east = origin.to_geodetic(0.0, 100.0, 0.0)
    assert -180.0 <= east.lon_deg < -179.99
    west = LocalOrigin(0.0, -179.9999, 0.0).to_geodetic(0.0, -100.0, 0.0)
    assert 179.99 < west.lon_deg < 180.0


def test_far_home_does_not_break_rtl(make_harness: HarnessFactory) -> None:
    harness = make_harness()
    harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    harness.arm()
    harness.run_until(lambda: harness.vehicle.mode_name == "AUTO_LOITER", timeout_s=30.0)
    harness.command_long(SET_HOME, 0, 0, 0, 0, -47.397742, -171.454406, 489.4)
    harness.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    harness.api.clear()
    harness.run(3.0)
    assert harness.vehicle.mode_name == "AUTO_RTL"
    assert_positions_on_the_globe(harness)


def test_real_quad_keeps_running_when_origin_and_home_jump_across_the_globe() -> None:
    harness = Harness(SimVehicle("quad"))
    harness.wait_ready()
    harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    harness.arm()
    harness.run_until(lambda: harness.vehicle.mode_name == "AUTO_LOITER", timeout_s=20.0)
    set_origin(harness, -90.0, 180.0, -1.0e3)
    harness.command_long(SET_HOME, 0, 0, 0, 0, 0.0, -179.9999999, 1.0e5)
    assert harness.last_ack(SET_HOME) == ACCEPTED
    harness.api.clear()
    harness.run(2.0)
    assert_positions_on_the_globe(harness)
    truth = harness.vehicle.truth
    assert all(math.isfinite(x) for x in (*truth.position_ned_m, *truth.velocity_ned_m_s))
    assert len(harness.api.of_type("HEARTBEAT")) >= 1
