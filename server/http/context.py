"""The API's context and the checks every call makes before it runs (token, role, vehicle,
connection), with no web framework: the REST dependencies (``deps``), the sockets and the
fleet edge make them alike."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Protocol

from server.control.audit import AuditLog
from server.control.auth import Role, TokenChecker
from server.control.deadman import Deadman
from server.control.lease import LeaseManager
from server.control.lease_ops import holder_name
from server.control.registry import VehicleRegistry
from server.http.errors import ApiError
from server.http.guards import Guards
from server.http.tile_archive import TileArchive
from server.link import Vehicle
from server.settings import Settings


class Peer(Protocol):
    """Where a connection comes from (Starlette's ``Address``)."""

    @property
    def host(self) -> str: ...
    @property
    def port(self) -> int: ...


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

    def holder_name(self, client_name: str | None, session: str, client: Peer | None) -> str:
        """A session's name (lease_ops.holder_name)."""
        where = (client.host, client.port) if client else None
        return holder_name(self.pilot_name, client_name, session, where)


READ_ONLY_REASON = "read-only replay: this server shows a recording and sends nothing"


def role_of(context: ApiContext, token: str | None) -> Role:
    """The token's role, or 401."""
    role = context.tokens.role_of(token)
    if role is None:
        raise ApiError(401, "missing or wrong token", headers={"WWW-Authenticate": "Bearer"})
    return role


def pilot_only(context: ApiContext, role: Role) -> Role:
    """The pilot's role, or 403 (an observer, or a read-only replay)."""
    if context.read_only:
        raise ApiError(403, READ_ONLY_REASON)
    if role is not Role.PILOT:
        raise ApiError(403, "observer tokens may only read; this call needs the pilot token")
    return role


def known_vehicle(context: ApiContext, vehicle_id: int) -> Vehicle:
    """The vehicle, or 404."""
    vehicle = context.registry.get(vehicle_id)
    if vehicle is None:
        raise ApiError(404, f"no vehicle {vehicle_id}")
    return vehicle


def require_connected(vehicle: Vehicle) -> Vehicle:
    if not vehicle.connected:
        why = vehicle.lost_reason
        raise ApiError(503, f"vehicle {vehicle.sysid} is not connected"
                            + (f": {why}" if why else ""))
    return vehicle
