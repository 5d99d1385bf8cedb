"""The real MAVSDK (mavsdk_server) flies the simulated vehicle like PX4 SITL."""

from __future__ import annotations

import math
from typing import Any

import pytest

from tests.peers.conftest import MavsdkFactory, first
from tests.waiting import wait_for

pytestmark = pytest.mark.peers


def ned_distance_m(a: list[float], b: list[float]) -> float:
    return math.dist(a, b)


async def test_connect_health_and_telemetry(mavsdk_drone: MavsdkFactory) -> None:
    drone, sim = await mavsdk_drone(speed=2.0)
    telemetry = drone.telemetry
    assert await first(telemetry.health_all_ok(), bool, 20.0)
    position = await first(telemetry.position(), lambda p: True, 5.0)
    assert position.latitude_deg == pytest.approx(47.397742, abs=1e-5)
    assert position.absolute_altitude_m == pytest.approx(489.4, abs=0.5)
    attitude = await first(telemetry.attitude_euler(), lambda a: True, 5.0)
    assert abs(attitude.roll_deg) < 5
    assert abs(attitude.pitch_deg) < 5
    assert str(await first(telemetry.flight_mode(), lambda m: True, 5.0)) == "HOLD"
    assert await first(telemetry.armed(), lambda a: True, 5.0) is False
    assert str(await first(telemetry.landed_state(), lambda s: True, 5.0)) == "ON_GROUND"
    battery = await first(telemetry.battery(), lambda b: True, 10.0)
    assert 12.0 < battery.voltage_v < 17.0
    assert battery.remaining_percent > 50
    home = await first(telemetry.home(), lambda h: True, 10.0)
    assert home.latitude_deg == pytest.approx(47.397742, abs=1e-5)
    await drone.action.set_takeoff_altitude(4.0)
    assert await drone.action.get_takeoff_altitude() == pytest.approx(4.0)
    assert sim.instances[0].vehicle.params.get("MIS_TAKEOFF_ALT") == pytest.approx(4.0)


async def _flying(
    mavsdk_drone: MavsdkFactory, altitude_m: float, timeout_s: float, **sim: Any
) -> tuple[Any, Any]:
    """A MAVSDK drone on a new sim, armed, taken off and holding at altitude_m (PX4 holds
    once there); the drone and the sim's vehicle."""
    drone, cluster = await mavsdk_drone(**sim)
    await first(drone.telemetry.health_all_ok(), bool, 20.0)
    await drone.action.set_takeoff_altitude(altitude_m)
    await drone.action.arm()
    await drone.action.takeoff()
    await first(drone.telemetry.flight_mode(), lambda m: str(m) == "HOLD", timeout_s)
    return drone, cluster.instances[0].vehicle


async def test_arm_takeoff_offboard_position_velocity_and_stop(
    mavsdk_drone: MavsdkFactory,
) -> None:
    from mavsdk_grpc.offboard import PositionNedYaw, VelocityNedYaw

    drone, vehicle = await _flying(mavsdk_drone, 5.0, 30.0)
    assert vehicle.armed
    assert -vehicle.truth.position_ned_m[2] > 4.0

    target = [5.0, -3.0, -6.0]
    await drone.offboard.set_position_ned(PositionNedYaw(*target, 0.0))
    await drone.offboard.start()
    assert vehicle.mode_name == "OFFBOARD"
    await wait_for(lambda: ned_distance_m(vehicle.truth.position_ned_m, target) < 0.5, 20.0,
                   "offboard position")

    await drone.offboard.set_velocity_ned(VelocityNedYaw(2.0, 0.0, 0.0, 0.0))
    await wait_for(lambda: abs(vehicle.truth.velocity_ned_m_s[0] - 2.0) < 0.3, 20.0,
                   "offboard velocity")

    await drone.offboard.stop()
    await first(drone.telemetry.flight_mode(), lambda m: str(m) == "HOLD", 10.0)
    await wait_for(lambda: math.hypot(*vehicle.truth.velocity_ned_m_s[:2]) < 0.5, 10.0,
                   "stop after offboard")


async def test_goto_location_then_return_to_launch_lands_at_home(
    mavsdk_drone: MavsdkFactory,
) -> None:
    drone, vehicle = await _flying(mavsdk_drone, 10.0, 40.0)
    home = await first(drone.telemetry.home(), lambda h: True, 10.0)

    goal = vehicle.origin.to_geodetic(15.0, 0.0, 0.0)
    await drone.action.goto_location(goal.lat_deg, goal.lon_deg, home.absolute_altitude_m + 10,
                                     0.0)
    await wait_for(lambda: abs(vehicle.truth.position_ned_m[0] - 15.0) < 1.0, 30.0, "goto")

    await drone.action.return_to_launch()
    await first(drone.telemetry.armed(), lambda armed: not armed, 60.0)
    north, east, _ = vehicle.truth.position_ned_m
    assert math.hypot(north - home.local_north_m, east - home.local_east_m) < 1.0
    assert str(await first(drone.telemetry.landed_state(), lambda s: True, 5.0)) == "ON_GROUND"


async def test_vtol_transitions_to_fixed_wing_and_back(mavsdk_drone: MavsdkFactory) -> None:
    from sim.models import airframes

    try:
        airframes.make_airframe("vtol", airframes.default_params("vtol"))
    except (ValueError, KeyError):
        pytest.skip("the vtol airframe model is not available yet")
    drone, _vehicle = await _flying(mavsdk_drone, 30.0, 60.0, airframe="vtol")
    await drone.action.transition_to_fixedwing()
    await first(drone.telemetry.vtol_state(), lambda s: str(s) == "FW", 30.0)
    await drone.action.transition_to_multicopter()
    await first(drone.telemetry.vtol_state(), lambda s: str(s) == "MC", 30.0)


async def test_every_telemetry_subscription_delivers_on_a_vtol(
    mavsdk_drone: MavsdkFactory,
) -> None:
    # MAVSDK reads gps_info from GPS_RAW_INT and the VTOL state from EXTENDED_SYS_STATE on
    # the onboard link, as PX4 sends them there
    drone, _sim = await mavsdk_drone(airframe="vtol", speed=2.0)
    telemetry = drone.telemetry
    assert await first(telemetry.health_all_ok(), bool, 20.0)
    gps = await first(telemetry.gps_info(), lambda g: True, 5.0)
    assert str(gps.fix_type) == "FIX_3D"
    assert gps.num_satellites > 6
    health = await first(telemetry.health(), lambda h: True, 5.0)
    assert health.is_global_position_ok
    assert health.is_home_position_ok
    assert str(await first(telemetry.vtol_state(), lambda s: True, 5.0)) == "MC"
    await first(telemetry.position(), lambda p: True, 5.0)
    await first(telemetry.attitude_quaternion(), lambda q: True, 5.0)
    assert (await first(telemetry.battery(), lambda b: True, 5.0)).remaining_percent > 50
    assert str(await first(telemetry.flight_mode(), lambda m: True, 5.0)) == "HOLD"
    assert str(await first(telemetry.landed_state(), lambda s: True, 5.0)) == "ON_GROUND"
