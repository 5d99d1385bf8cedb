"""Vehicle commands by name, with their request bodies: the REST routes and the WebSocket
control session run the same table, so both refuse and answer alike."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel

from server.api import schemas
from server.api.errors import ApiError
from server.link import CommandResult, Vehicle
from server.link.geo import ground_distance_m


class NoBody(BaseModel):
    pass


@dataclass(frozen=True)
class Operation:
    body: type[BaseModel]
    run: Callable[[Vehicle, Any], Awaitable[CommandResult]]


async def arm(vehicle: Vehicle, body: schemas.ArmBody) -> CommandResult:
    return await vehicle.arm(force=body.force)


async def disarm(vehicle: Vehicle, body: schemas.ArmBody) -> CommandResult:
    return await vehicle.disarm(force=body.force)


async def takeoff(vehicle: Vehicle, body: schemas.TakeoffBody) -> CommandResult:
    limit = vehicle.envelope.max_alt_rel_m
    if body.altitude_m is not None and limit is not None and body.altitude_m > limit:
        raise ApiError(422, "takeoff altitude above the envelope", field="altitude_m", limit=limit)
    return await vehicle.takeoff(body.altitude_m)


async def land(vehicle: Vehicle, _: NoBody) -> CommandResult:
    return await vehicle.land()


async def rtl(vehicle: Vehicle, _: NoBody) -> CommandResult:
    return await vehicle.return_to_launch()


async def hold(vehicle: Vehicle, _: NoBody) -> CommandResult:
    return await vehicle.hold()


async def set_mode(vehicle: Vehicle, body: schemas.ModeBody) -> CommandResult:
    return await vehicle.set_mode(body.mode)


async def reposition(vehicle: Vehicle, body: schemas.RepositionBody) -> CommandResult:
    _check_reposition_envelope(vehicle, body)
    return await vehicle.reposition(
        body.lat_deg,
        body.lon_deg,
        alt_amsl_m=body.alt_amsl_m,
        alt_rel_m=body.alt_rel_m,
        ground_speed_m_s=body.ground_speed_m_s,
        yaw_deg=body.yaw_deg,
        loiter_radius_m=body.loiter_radius_m,
    )


async def vtol_transition(vehicle: Vehicle, body: schemas.VtolTransitionBody) -> CommandResult:
    return await vehicle.vtol_transition(
        body.to == "fixed_wing", immediate=body.immediate, wait=body.wait
    )


async def set_origin(vehicle: Vehicle, body: schemas.OriginBody) -> CommandResult:
    return await vehicle.set_gps_origin(body.lat_deg, body.lon_deg, body.alt_amsl_m)


async def set_home(vehicle: Vehicle, body: schemas.HomeBody) -> CommandResult:
    return await vehicle.set_home(body.lat_deg, body.lon_deg, body.alt_amsl_m)


async def offboard_start(vehicle: Vehicle, body: schemas.OffboardStartBody) -> CommandResult:
    setpoint = body.setpoint.to_link() if body.setpoint is not None else None
    return await vehicle.start_offboard(setpoint)


async def offboard_stop(vehicle: Vehicle, body: schemas.OffboardStopBody) -> CommandResult:
    return await vehicle.stop_offboard(body.then_mode)


OPERATIONS: dict[str, Operation] = {
    "arm": Operation(schemas.ArmBody, arm),
    "disarm": Operation(schemas.ArmBody, disarm),
    "takeoff": Operation(schemas.TakeoffBody, takeoff),
    "land": Operation(NoBody, land),
    "rtl": Operation(NoBody, rtl),
    "hold": Operation(NoBody, hold),
    "mode": Operation(schemas.ModeBody, set_mode),
    "reposition": Operation(schemas.RepositionBody, reposition),
    "vtol_transition": Operation(schemas.VtolTransitionBody, vtol_transition),
    "origin": Operation(schemas.OriginBody, set_origin),
    "home": Operation(schemas.HomeBody, set_home),
    "offboard_start": Operation(schemas.OffboardStartBody, offboard_start),
    "offboard_stop": Operation(schemas.OffboardStopBody, offboard_stop),
}


def _check_reposition_envelope(vehicle: Vehicle, body: schemas.RepositionBody) -> None:
    """The envelope guards repositions as it guards setpoints: they fly the vehicle too."""
    envelope = vehicle.envelope
    home = vehicle.snapshot().home
    if home is None:
        return
    if envelope.max_alt_rel_m is not None:
        alt_rel_m = body.alt_rel_m
        if alt_rel_m is None and body.alt_amsl_m is not None:
            alt_rel_m = body.alt_amsl_m - home.alt_amsl_m
        if alt_rel_m is not None and alt_rel_m > envelope.max_alt_rel_m:
            raise ApiError(
                422,
                "reposition altitude above the envelope",
                field="alt_rel_m" if body.alt_rel_m is not None else "alt_amsl_m",
                limit=envelope.max_alt_rel_m,
            )
    if envelope.max_distance_m is not None:
        distance_m = ground_distance_m(home.lat_deg, home.lon_deg, body.lat_deg, body.lon_deg)
        if distance_m > envelope.max_distance_m:
            raise ApiError(
                422,
                f"reposition target {distance_m:.0f} m from home, beyond the envelope",
                field="lat_deg",
                limit=envelope.max_distance_m,
            )
