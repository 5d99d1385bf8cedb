"""Request dependencies as Annotated aliases: context, token role, vehicle lookup, lease.

All are coroutines so they run on the event loop, which owns the leases and the links
(FastAPI would run plain functions in its thread pool)."""

from __future__ import annotations

import contextlib
import functools
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Header, Path, Request, Security
from fastapi.security import APIKeyQuery, HTTPAuthorizationCredentials, HTTPBearer
from starlette.datastructures import Address
from starlette.requests import HTTPConnection

from server.control.audit import AuditLog
from server.control.auth import Role, TokenChecker, token_from
from server.control.deadman import Deadman
from server.control.lease import Lease, LeaseInvalid, LeaseManager
from server.control.lease_ops import holder_name
from server.control.registry import VehicleRegistry
from server.http.contract import input_first
from server.http.errors import ApiError
from server.http.security import Guards
from server.http.tile_archive import TileArchive
from server.link import Vehicle
from server.settings import Settings


@dataclass
class ApiContext:
    settings: Settings
    tokens: TokenChecker
    registry: VehicleRegistry
    leases: LeaseManager
    deadman: Deadman
    # A replayed recording: nobody may control, whatever the token.
    read_only: bool = False
    # the offline map's tiles (settings.map_tiles), opened when the app is built
    tiles: TileArchive | None = None

    @functools.cached_property
    def guards(self) -> Guards:
        """Rate limits and the wrong-token lockout (security.py), from the settings."""
        return Guards.from_settings(self.settings)

    @property
    def audit(self) -> AuditLog:
        return self.deadman.audit

    @property
    def pilot_name(self) -> str:
        return self.tokens.name_of(Role.PILOT)

    def holder_name(self, client_name: str | None, session: str, client: Address | None) -> str:
        """A session's name (lease_ops.holder_name)."""
        where = (client.host, client.port) if client else None
        return holder_name(self.pilot_name, client_name, session, where)


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


def role_of(context: ApiContext, token: str | None) -> Role:
    """The token's role, or 401."""
    role = context.tokens.role_of(token)
    if role is None:
        raise ApiError(401, "missing or wrong token", headers={"WWW-Authenticate": "Bearer"})
    return role


Reader = Annotated[Role, Depends(get_role)]


READ_ONLY_REASON = "read-only replay: this server shows a recording and sends nothing"


async def require_pilot(role: Reader, context: Context) -> Role:
    return pilot_only(context, role)


def pilot_only(context: ApiContext, role: Role) -> Role:
    """The pilot's role, or 403 (an observer, or a read-only replay)."""
    if context.read_only:
        raise ApiError(403, READ_ONLY_REASON)
    if role is not Role.PILOT:
        raise ApiError(403, "observer tokens may only read; this call needs the pilot token")
    return role


Pilot = Annotated[Role, Depends(require_pilot)]
VehicleId = Annotated[int, Path(ge=0, le=255, description="the vehicle's MAVLink sysid")]


async def get_vehicle(vehicle_id: VehicleId, context: Context, _: Reader) -> Vehicle:
    return known_vehicle(context, vehicle_id)


def known_vehicle(context: ApiContext, vehicle_id: int) -> Vehicle:
    """The vehicle, or 404."""
    vehicle = context.registry.get(vehicle_id)
    if vehicle is None:
        raise ApiError(404, f"no vehicle {vehicle_id}")
    return vehicle


KnownVehicle = Annotated[Vehicle, Depends(get_vehicle)]


def require_connected(vehicle: Vehicle) -> Vehicle:
    if not vehicle.connected:
        raise ApiError(503, f"vehicle {vehicle.sysid} is not connected (no HEARTBEAT)")
    return vehicle


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
