"""Intents against the simulated vehicle over UDP: brake then hold, velocity with an
altitude hold, offset and go-to moves (the targets checked with pymap3d, independently of
the code under test), and the envelope's refusals."""

from __future__ import annotations

import math

import pymap3d
import pytest

from server.link import intents
from server.link.codec.envelope import Envelope, SetpointRejected, check_takeoff_altitude
from server.link.codec.setpoint_checks import Reference, check
from server.link.codec.setpoints import PositionNed, RawLocal, VelocityNed
from server.link.core.state import GlobalState, HomeState
from server.link.vehicle import Vehicle
from tests.link.conftest import SimSession, open_sim, wait_for
from tests.waiting import holds_for

SPEED = 5.0  # sim seconds per wall second


def _speed_m_s(vehicle: Vehicle) -> float:
    speed = intents.speed_m_s(vehicle)
    return math.inf if speed is None else speed


def _alt_rel_m(vehicle: Vehicle) -> float:
    position = vehicle.telemetry.global_position
    return position.alt_rel_m if position is not None else math.nan


def _ground_distance_to_m(vehicle: Vehicle, lat_deg: float, lon_deg: float) -> float:
    here = vehicle.telemetry.global_position
    assert here is not None
    north_m, east_m, _ = pymap3d.geodetic2ned(lat_deg, lon_deg, 0.0, here.lat_deg,
                                              here.lon_deg, 0.0)  # fmt: skip
    return math.hypot(north_m, east_m)


def _point_from(
    ref: GlobalState | HomeState, north_m: float, east_m: float, down_m: float = 0.0
) -> tuple[float, float]:
    """(lat, lon) of a point seen from ref, by pymap3d: the expected answer of a move."""
    lat_deg, lon_deg, _ = pymap3d.ned2geodetic(
        north_m, east_m, down_m, ref.lat_deg, ref.lon_deg, ref.alt_amsl_m
    )
    return lat_deg, lon_deg


async def _arrives(
    vehicle: Vehicle, lat_deg: float, lon_deg: float, alt_rel_m: float | None, *, within_m: float
) -> None:
    """Wait until the vehicle is within_m of the point (and of the altitude, if given)."""

    def there() -> bool:
        if _ground_distance_to_m(vehicle, lat_deg, lon_deg) >= within_m:
            return False
        return alt_rel_m is None or abs(_alt_rel_m(vehicle) - alt_rel_m) < within_m

    await wait_for(there, 40 / SPEED, f"arrival at {lat_deg:.6f}, {lon_deg:.6f}")


async def _hovering(session: SimSession, *, offboard: bool = False) -> Vehicle:
    """Armed and 5 m up (holding there in OFFBOARD, with offboard)."""
    vehicle = session.vehicle
    assert (await vehicle.arm()).ok
    assert (await vehicle.takeoff(5.0)).ok
    await wait_for(lambda: _alt_rel_m(vehicle) > 4.4, 40 / SPEED, "takeoff")
    if offboard:
        assert (await vehicle.start_offboard()).ok
    return vehicle


async def test_brake_stops_and_holds_where_it_stopped_without_flying_back() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = await _hovering(session)
        assert (await vehicle.start_offboard(VelocityNed(4.0, 0.0, 0.0, yaw_deg=0))).ok
        await wait_for(lambda: _speed_m_s(vehicle) > 3.5, 20 / SPEED, "4 m/s north")
        events = vehicle.subscribe_events(maxsize=1024)
        braked_at_north_m = session.truth_ned_m[0]

        result = await intents.brake(vehicle)

        assert result.via == "setpoint"
        assert result.sent is not None
        assert result.sent.setpoint.kind == "velocity_ned"
        await wait_for(lambda: isinstance(vehicle.offboard.setpoint, PositionNed), 20 / SPEED,
                       "the hold")  # fmt: skip
        hold = vehicle.offboard.setpoint
        assert isinstance(hold, PositionNed)
        # it held ahead of where the brake began, within a braking distance from 4 m/s
        assert braked_at_north_m < hold.north_m < braked_at_north_m + 6.0
        await holds_for(lambda: math.dist(session.truth_ned_m, (hold.north_m, hold.east_m,
                                                                hold.down_m)) < 1.0,
                        1.0, "holding there")  # fmt: skip
        phases = []
        while not events.empty():
            event = events.get_nowait()
            if event.kind == "intent":
                phases.append(event.data["phase"])
        assert phases == ["braking", "holding"]


async def test_a_new_intent_during_the_brake_wins_over_the_hold() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = await _hovering(session)
        assert (await vehicle.start_offboard(VelocityNed(4.0, 0.0, 0.0, yaw_deg=0))).ok
        await wait_for(lambda: _speed_m_s(vehicle) > 3.5, 20 / SPEED, "4 m/s north")

        await intents.brake_then_hold(vehicle)
        await intents.velocity(vehicle, frame="ned", x_m_s=0.0, y_m_s=2.0)
        await wait_for(lambda: vehicle.telemetry.velocity_ned is not None
                       and vehicle.telemetry.velocity_ned.east_m_s > 1.7, 20 / SPEED,
                       "2 m/s east")  # fmt: skip

        assert isinstance(vehicle.offboard.setpoint, VelocityNed)
        assert vehicle.offboard.setpoint.east_m_s == 2.0


async def test_velocity_with_altitude_hold_keeps_the_altitude_it_started_at() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = await _hovering(session, offboard=True)
        start_down_m = session.truth_ned_m[2]

        first = await intents.velocity(vehicle, frame="body", x_m_s=3.0, y_m_s=0.0,
                                       hold_altitude=True)  # fmt: skip
        await wait_for(lambda: _speed_m_s(vehicle) > 2.7, 20 / SPEED, "3 m/s forward")
        again = await intents.velocity(vehicle, frame="body", x_m_s=2.0, y_m_s=0.0,
                                       hold_altitude=True)  # fmt: skip

        assert first.sent is not None
        assert again.sent is not None
        held, renewed = first.sent.setpoint, again.sent.setpoint
        assert isinstance(held, RawLocal)
        assert isinstance(renewed, RawLocal)
        assert held.z == pytest.approx(start_down_m, abs=0.3)
        assert renewed.z == held.z  # the altitude of the first call, not the one now
        await holds_for(lambda: abs(session.truth_ned_m[2] - held.z) < 0.5, 1.0, "altitude held")


async def test_offset_in_offboard_arrives_at_the_point_pymap3d_gives() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = await _hovering(session, offboard=True)
        here = vehicle.telemetry.global_position
        assert here is not None
        lat_deg, lon_deg = _point_from(here, 12.0, -7.0, -2.0)

        result = await intents.offset(vehicle, north_m=12.0, east_m=-7.0, up_m=2.0)

        assert result.via == "setpoint"
        assert result.target is not None
        assert (result.target.lat_deg, result.target.lon_deg) == pytest.approx(
            (lat_deg, lon_deg), abs=1e-9
        )
        assert result.target.alt_rel_m == pytest.approx(here.alt_rel_m + 2.0)
        await _arrives(vehicle, lat_deg, lon_deg, here.alt_rel_m + 2.0, within_m=0.5)
        assert vehicle.telemetry.mode == "OFFBOARD"


async def test_offset_and_goto_outside_offboard_are_repositions() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = await _hovering(session)
        here = vehicle.telemetry.global_position
        assert here is not None
        lat_deg, lon_deg = _point_from(here, 10.0, 0.0)

        moved = await intents.offset(vehicle, north_m=10.0, east_m=0.0)
        assert moved.via == "reposition"
        assert moved.command is not None
        assert moved.command.ok
        await _arrives(vehicle, lat_deg, lon_deg, None, within_m=1.0)

        back = await intents.goto(vehicle, lat_deg=here.lat_deg, lon_deg=here.lon_deg,
                                  alt_rel_m=7.0)  # fmt: skip
        assert back.via == "reposition"
        assert back.ok
        await _arrives(vehicle, here.lat_deg, here.lon_deg, 7.0, within_m=0.6)
        assert vehicle.telemetry.mode == "HOLD"


async def test_goto_in_offboard_streams_a_global_position_and_arrives() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = await _hovering(session, offboard=True)
        home = vehicle.telemetry.home
        assert home is not None
        lat_deg, lon_deg = _point_from(home, -8.0, 9.0)

        result = await intents.goto(vehicle, lat_deg=lat_deg, lon_deg=lon_deg, alt_rel_m=6.0)

        assert result.via == "setpoint"
        assert result.sent is not None
        assert result.sent.setpoint.kind == "position_global"
        await _arrives(vehicle, lat_deg, lon_deg, 6.0, within_m=0.5)
        assert vehicle.telemetry.mode == "OFFBOARD"


async def test_moves_outside_the_envelope_are_refused_naming_the_limit() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        await wait_for(lambda: vehicle.telemetry.home is not None
                       and vehicle.telemetry.global_position is not None, 10.0,
                       "home")  # fmt: skip
        home = vehicle.telemetry.home
        assert home is not None
        far_lat, far_lon = _point_from(home, 0.0, 501.0)

        with pytest.raises(SetpointRejected) as far:
            await intents.goto(vehicle, lat_deg=far_lat, lon_deg=far_lon, alt_rel_m=10.0)
        with pytest.raises(SetpointRejected) as high:
            await intents.offset(vehicle, north_m=0.0, east_m=0.0, up_m=130.0)
        with pytest.raises(SetpointRejected) as fast:
            await intents.velocity(vehicle, frame="ned", x_m_s=13.0, y_m_s=0.0)

        assert (far.value.field, far.value.limit) == ("lat_deg", 500.0)
        assert far.value.reason.startswith(
            "goto outside the envelope: distance_m 501.0 > max_distance_m 500"
        )
        assert (high.value.field, high.value.limit) == ("up_m", 120.0)
        assert "max_alt_rel_m 120" in high.value.reason
        assert (fast.value.field, fast.value.limit) == ("max_speed_xy_m_s", 12.0)
        assert not vehicle.streamer_active  # nothing was sent


def test_takeoff_altitude_is_held_to_the_envelope() -> None:
    check_takeoff_altitude(Envelope(), 120.0)
    check_takeoff_altitude(Envelope(), None)  # PX4's own MIS_TAKEOFF_ALT
    check_takeoff_altitude(Envelope(max_alt_rel_m=None), 5000.0)
    with pytest.raises(SetpointRejected) as refused:
        check_takeoff_altitude(Envelope(), 121.0)
    assert (refused.value.reason, refused.value.field, refused.value.limit) == (
        "takeoff altitude above the envelope",
        "altitude_m",
        120.0,
    )


def test_an_altitude_hold_is_checked_on_the_axes_px4_reads() -> None:
    # x/y position, z velocity, acceleration and yaw rate ignored: velocity x/y at a height
    mask = 1 | 2 | 32 | 64 | 128 | 256 | 2048
    home = Reference((0.0, 0.0, 0.0), None)
    far_x = RawLocal(frame=1, type_mask=mask, x=900.0, z=-10.0, vx=2.0)
    check(far_x, "multicopter", Envelope(), home)  # the ignored x is no distance from home
    with pytest.raises(SetpointRejected) as high:
        check(RawLocal(frame=1, type_mask=mask, z=-130.0, vx=2.0), "multicopter", Envelope(), home)
    assert (high.value.field, high.value.limit) == ("max_alt_rel_m", 120.0)
