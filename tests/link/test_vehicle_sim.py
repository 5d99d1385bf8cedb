"""The Vehicle against the simulated PX4 vehicle (faster than real time): discovery,
arming, takeoff, offboard position / velocity / body velocity, reposition, RTL, VTOL
transitions, parameters."""

from __future__ import annotations

import math

import pytest

from server.link.codec.commands import CommandOutcome
from server.link.codec.setpoints import PositionNed, VelocityBody, VelocityNed
from server.link.core.state import HomeState
from server.link.plugins.params import ParamUnknown
from server.link.vehicle import Vehicle
from tests.link.conftest import SimSession, arm_as_sent, drain, open_sim, wait_for

SPEED = 5.0  # sim seconds per wall second


def _alt_rel_m(vehicle: Vehicle) -> float:
    position = vehicle.snapshot().global_position
    return position.alt_rel_m if position is not None else math.nan


def _distance_m(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    return math.dist(a, b)


async def _take_off(session: SimSession, altitude_rel_m: float) -> HomeState:
    """Arm, climb to altitude_rel_m; the home it took off from."""
    vehicle = session.vehicle
    assert (await vehicle.arm()).ok
    assert (await vehicle.takeoff(altitude_rel_m)).ok
    await wait_for(lambda: _alt_rel_m(vehicle) > altitude_rel_m - 0.6, 40 / SPEED, "takeoff")
    home = vehicle.snapshot().home
    assert home is not None
    return home


async def test_vehicle_is_discovered_with_type_home_and_both_modes() -> None:
    async with open_sim(speed=SPEED) as session:
        await wait_for(lambda: session.vehicle.snapshot().user_mode is not None, 2.0,
                       "CURRENT_MODE")  # fmt: skip
        state = session.vehicle.snapshot()

    assert (state.mav_type, state.autopilot) == ("QUADROTOR", "PX4")
    assert state.connected
    assert not state.armed
    assert state.mode == state.user_mode
    assert state.home is not None
    assert state.home.lat_deg == pytest.approx(47.397742, abs=1e-4)
    assert state.landed_state == "ON_GROUND"


async def test_gps_origin_is_known_once_the_vehicle_has_a_position() -> None:
    async with open_sim(speed=SPEED) as session:
        await wait_for(lambda: session.vehicle.snapshot().origin is not None, 10.0, "origin")
        origin = session.vehicle.snapshot().origin

    assert origin is not None
    assert (origin.lat_deg, origin.lon_deg) == pytest.approx((47.397742, 8.545594), abs=1e-6)


async def test_early_refusals_of_home_and_origin_are_cleared_once_they_come() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        await wait_for(
            lambda: vehicle.snapshot().origin is not None and vehicle.snapshot().home is not None,
            10.0,
            "home and origin",
        )
        await wait_for(lambda: not vehicle.snapshot().telemetry_refused, 5.0, "no refusals")


async def test_offboard_position_setpoint_is_reached_within_half_a_metre() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        home = await _take_off(session, 5.0)
        target = (5.0, 3.0, home.down_m - 6.0)

        result = await vehicle.start_offboard(PositionNed(*target, yaw_deg=0))
        await wait_for(lambda: _distance_m(session.truth_ned_m, target) < 0.5, 30 / SPEED,
                       "arrival")  # fmt: skip

        assert result.ok
        assert vehicle.snapshot().mode == "OFFBOARD"
        assert vehicle.streamer_active


async def test_velocity_and_body_velocity_setpoints_move_the_vehicle() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        await _take_off(session, 5.0)

        def velocity() -> tuple[float, float]:
            v = vehicle.snapshot().velocity_ned
            return (v.north_m_s, v.east_m_s) if v is not None else (math.nan, math.nan)

        assert (await vehicle.start_offboard(VelocityNed(2.0, 0.0, 0.0, yaw_deg=90))).ok
        await wait_for(lambda: abs(velocity()[0] - 2.0) < 0.3, 20 / SPEED, "2 m/s north")
        await wait_for(
            lambda: abs((vehicle.snapshot().heading_deg or 0.0) - 90.0) < 5, 20 / SPEED, "yaw"
        )

        await vehicle.set_setpoint(VelocityBody(forward_m_s=0.0, right_m_s=2.0, down_m_s=0.0))
        # facing east, "right" is south
        await wait_for(lambda: velocity()[0] < -1.7 and abs(velocity()[1]) < 0.3, 20 / SPEED,
                       "2 m/s to the right")  # fmt: skip


async def test_reposition_flies_to_the_target_and_holds() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        home = await _take_off(session, 5.0)
        lat_deg = home.lat_deg + 15.0 / 111_195.0  # 15 m north

        result = await vehicle.reposition(lat_deg, home.lon_deg, alt_rel_m=8.0)
        await wait_for(lambda: _distance_m(session.truth_ned_m, (15.0, 0.0, -8.0)) < 1.0,
                       40 / SPEED, "arrival")  # fmt: skip

        assert result.ok
        assert vehicle.snapshot().mode == "HOLD"


async def test_rtl_lands_and_disarms_at_home_and_ends_the_stream() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        # return at the altitude it already has: no climb to PX4's default 30 m first
        assert await vehicle.set_param("RTL_RETURN_ALT", 8.0) == 8.0
        await _take_off(session, 5.0)
        await vehicle.start_offboard(PositionNed(12.0, -6.0, -8.0, yaw_deg=0))
        await wait_for(lambda: _distance_m(session.truth_ned_m, (12, -6, -8)) < 1.0, 40 / SPEED)
        events = vehicle.subscribe_events(maxsize=1024)

        assert (await vehicle.return_to_launch()).ok
        await wait_for(lambda: not vehicle.snapshot().armed, 120 / SPEED, "landed and disarmed")

        assert math.dist(session.truth_ned_m[:2], (0.0, 0.0)) < 1.0
        assert vehicle.snapshot().landed_state == "ON_GROUND"
        assert not vehicle.streamer_active
        seen = [e.data["phase"] for e in drain(events) if e.kind == "rtl"]
        assert "LANDED" in seen


async def test_vtol_transitions_to_fixed_wing_and_back() -> None:
    async with open_sim(airframe="vtol", speed=SPEED) as session:
        vehicle = session.vehicle
        await _take_off(session, 20.0)
        await wait_for(lambda: vehicle.snapshot().mode == "HOLD", 10 / SPEED, "takeoff done")

        forward = await vehicle.vtol_transition(to_fixed_wing=True, timeout_s=30 / SPEED)
        assert forward.ok, forward
        assert vehicle.snapshot().vtol_state == "FW"

        back = await vehicle.vtol_transition(to_fixed_wing=False, timeout_s=30 / SPEED)
        assert back.ok, back
        assert vehicle.snapshot().vtol_state == "MC"


async def test_parameters_read_and_write_including_an_int() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle

        assert await vehicle.get_param("COM_RC_IN_MODE") == 1  # PX4 SITL's rcS sets it
        assert await vehicle.set_param("COM_RC_IN_MODE", 4) == 4
        assert await vehicle.get_param("COM_RC_IN_MODE") == 4
        assert await vehicle.set_param("MPC_XY_CRUISE", 7.5) == pytest.approx(7.5)
        assert session.sim.instances[0].vehicle.params.get("MPC_XY_CRUISE") == 7.5
        vehicle.params.timeout_s = 0.1  # PX4 stays silent: only the retries take time
        with pytest.raises(ParamUnknown):  # told by the whole list, read after the silence
            await vehicle.get_param("NO_SUCH_PARAM")


async def test_arming_refusal_in_offboard_without_signal_carries_the_reason() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        assert (await vehicle.set_mode("OFFBOARD")).ok  # disarmed: accepted

        result = await arm_as_sent(vehicle)

        assert result.outcome is CommandOutcome.TEMPORARILY_REJECTED
        assert result.reason is not None
        assert "denied" in result.reason.lower()


async def test_ready_to_arm_follows_px4s_prearm_bit_in_the_current_mode() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        await wait_for(lambda: vehicle.snapshot().ready_to_arm is True, 10.0, "ready to arm")
        assert (await vehicle.set_mode("OFFBOARD")).ok  # disarmed: accepted, no stream yet
        await wait_for(lambda: vehicle.snapshot().ready_to_arm is False, 5.0,
                       "no pre-arm bit in OFFBOARD without a setpoint stream")  # fmt: skip
        assert not (await arm_as_sent(vehicle)).ok
        await vehicle.set_setpoint(PositionNed(0.0, 0.0, -2.0))
        await wait_for(lambda: vehicle.snapshot().ready_to_arm is True, 5.0,
                       "the pre-arm bit back once setpoints stream")  # fmt: skip
        assert (await vehicle.arm()).ok
