"""Arming and taking off from any state a vehicle can be in on the ground, against the
simulated vehicle: a mode PX4 will not arm in for want of the pilot's choice is left for
Hold (arm) or Takeoff (takeoff) first; a refusal for a failing check stays the vehicle's."""

from __future__ import annotations

import pytest

from server.link.codec.commands import CommandOutcome
from server.link.codec.setpoints import PositionNed
from server.link.plugins.arming_modes import mode_to_arm_in
from server.link.vehicle import Vehicle
from tests.link.conftest import SimSession, open_sim, wait_for


@pytest.mark.parametrize(
    ("mode", "streaming", "expected"),
    [
        ("OFFBOARD", False, "HOLD"),
        ("OFFBOARD", True, None),
        ("RTL", False, "HOLD"),
        ("LAND", True, "HOLD"),
        ("HOLD", False, None),
        ("POSCTL", False, None),
        ("MISSION", False, None),
        ("TAKEOFF", False, None),
        ("TERMINATION", False, None),
        (None, False, None),
    ],
)
def test_the_mode_to_arm_in(mode: str | None, streaming: bool, expected: str | None) -> None:
    assert mode_to_arm_in(mode, streaming) == expected


async def _disarmed_in(session: SimSession, mode: str) -> Vehicle:
    vehicle = session.vehicle
    assert (await vehicle.set_mode(mode)).ok  # PX4 takes any mode while disarmed
    await wait_for(lambda: vehicle.snapshot().mode == mode, 3.0, mode)
    return vehicle


async def _armed_in(vehicle: Vehicle) -> str | None:
    """Arm; the mode the vehicle is armed in."""
    result = await vehicle.arm()
    assert result.ok, result
    await wait_for(lambda: vehicle.snapshot().armed, 3.0, "armed")
    return vehicle.snapshot().mode


@pytest.mark.parametrize("mode", ["OFFBOARD", "RTL", "LAND"])
async def test_arm_leaves_a_mode_px4_will_not_arm_in_for_hold(mode: str) -> None:
    async with open_sim(speed=2.0) as session:
        vehicle = await _disarmed_in(session, mode)

        assert await _armed_in(vehicle) == "HOLD"


async def test_arm_in_offboard_with_the_stream_running_stays_in_offboard() -> None:
    async with open_sim(speed=2.0) as session:
        vehicle = session.vehicle
        here = vehicle.snapshot().position_ned
        assert here is not None
        # the order stream -> OFFBOARD -> arm, which PX4 accepts
        await vehicle.set_setpoint(PositionNed(here.north_m, here.east_m, here.down_m))
        assert (await vehicle.set_mode("OFFBOARD")).ok

        assert await _armed_in(vehicle) == "OFFBOARD"


async def test_takeoff_from_offboard_without_a_stream_switches_to_takeoff_arms_and_climbs() -> None:
    async with open_sim(speed=2.0) as session:
        vehicle = await _disarmed_in(session, "OFFBOARD")

        result = await vehicle.takeoff(3.0)

        assert result.ok, result
        assert result.command == "MAV_CMD_NAV_TAKEOFF"
        await wait_for(lambda: _alt_rel_m(vehicle) > 1.0, 15.0, "the climb")


async def test_a_failing_check_in_the_pilots_mode_stays_a_refusal() -> None:
    async with open_sim(speed=2.0) as session:
        vehicle = await _disarmed_in(session, "MISSION")  # and no mission uploaded

        result = await vehicle.arm()

        assert result.outcome is CommandOutcome.TEMPORARILY_REJECTED
        assert result.reason is not None
        assert result.reason.startswith("Arming denied")
        assert vehicle.snapshot().mode == "MISSION"
        assert not vehicle.snapshot().armed


def _alt_rel_m(vehicle: Vehicle) -> float:
    where = vehicle.snapshot().global_position
    return where.alt_rel_m if where is not None else 0.0
