"""Request dependencies as Annotated aliases: context, token role, vehicle lookup, lease.

All are coroutines so they run on the event loop, which owns the leases and the links
(FastAPI would run plain functions in its thread pool)."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import Depends, Header, Path, Request, Security
from fastapi.security import APIKeyQuery, HTTPAuthorizationCredentials, HTTPBearer
from starlette.requests import HTTPConnection

from server.control.auth import Role, token_from
from server.control.lease import Lease, LeaseInvalid
from server.http.context import ApiContext, known_vehicle, pilot_only, require_connected, role_of
from server.http.contract import input_first
from server.link import Vehicle


async def get_context(connection: HTTPConnection) -> ApiContext:
    context: ApiContext = connection.app.state.api
    return context


Context = Annotated[ApiContext, Depends(get_context)]

# Declared so /docs offers both ways in; the lookup itself is token_from().
_bearer = HTTPBearer(auto_error=False, description="pilot or observer token")
_query_token = APIKeyQuery(name="token", auto_error=False, description="same token, in the URL")


async def get_role(
    request: Request,
    context: Context,
    _bearer_token: Annotated[HTTPAuthorizationCredentials | None, Security(_bearer)] = None,
    _query: Annotated[str | None, Security(_query_token)] = None,
) -> Role:
    return role_of(context, token_from(request.headers, request.query_params, request.cookies))


Reader = Annotated[Role, Depends(get_role)]


async def require_pilot(role: Reader, context: Context) -> Role:
    return pilot_only(context, role)


Pilot = Annotated[Role, Depends(require_pilot)]
VehicleId = Annotated[int, Path(ge=0, le=255, description="the vehicle's MAVLink sysid")]


async def get_vehicle(vehicle_id: VehicleId, context: Context, _: Reader) -> Vehicle:
    return known_vehicle(context, vehicle_id)


KnownVehicle = Annotated[Vehicle, Depends(get_vehicle)]


async def get_connected_vehicle(vehicle: KnownVehicle) -> Vehicle:
    return require_connected(vehicle)


ConnectedVehicle = Annotated[Vehicle, Depends(get_connected_vehicle)]

LeaseIdHeader = Annotated[
    str | None, Header(alias="X-Lease-Id", description="from POST /vehicles/{id}/control")
]


async def hold_lease(
    request: Request,
    _: Pilot,
    vehicle: KnownVehicle,
    context: Context,
    x_lease_id: LeaseIdHeader = None,
) -> AsyncIterator[Lease]:
    """Control calls renew the lease, and it cannot lapse while the call runs. A refused
    lease is answered for an input the schema allows; other input is a 422 first."""
    with contextlib.ExitStack() as held:
        try:
            lease = held.enter_context(context.leases.hold(vehicle.sysid, x_lease_id))
        except LeaseInvalid:
            await input_first(request)
            raise
        yield lease


async def get_controlled_vehicle(
    _lease: Annotated[Lease, Depends(hold_lease)], vehicle: KnownVehicle
) -> Vehicle:
    return require_connected(vehicle)


ControlledVehicle = Annotated[Vehicle, Depends(get_controlled_vehicle)]
