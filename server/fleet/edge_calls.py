"""A REST call that came over Zenoh, run on the control core without an HTTP hop: the
checks of the REST app in its order (the security middleware's lockout and rate limit, then
the route's token, pilot, vehicle, lease and connection checks, then its query and body
validated by the same models), then the function the REST route runs
(``server.http.vehicle_calls``). Refusals are answered by ``errors.error_status``, as the
app's error handlers answer them, so a call gets the same status and body either way.

Offered: every call under ``/api/v1/vehicles/{vehicle_id}`` (the table in
vehicle_calls.py); anything else is 404 (docs/fleet.md lists what the edge runs)."""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from typing import Any
from urllib.parse import parse_qsl

from server.control.auth import TokenChecker, token_from
from server.control.lease import LeaseInvalid
from server.control.lease_ops import Client
from server.control.publishers import StatePublishers
from server.http.context import (
    ApiContext,
    known_vehicle,
    pilot_only,
    require_connected,
    role_of,
)
from server.http.errors import ANSWERED_ERRORS, ApiError, error_status, validation_detail
from server.http.guards import Refusal, refusal_body, retry_after_header
from server.http.vehicle_calls import (
    VEHICLE_ID,
    Access,
    CallArgs,
    Reply,
    VehicleCall,
    match,
    validate,
    validated,
)
from server.link import Vehicle
from skyhelm_wire.calls import API_PREFIX, VEHICLE_PATH

log = logging.getLogger(__name__)

VEHICLES_PREFIX = API_PREFIX + VEHICLE_PATH.removesuffix("{vehicle_id}")
# the address the lockout counts a call that came over Zenoh against, and its client
ZENOH_ADDRESS = "zenoh"
ZENOH_CLIENT: Client = (ZENOH_ADDRESS, 0)
JSON = {"content-type": "application/json"}


class EdgeCalls:
    """Runs the calls the edge offers on this server's control core."""

    def __init__(self, context: ApiContext, publishers: StatePublishers) -> None:
        self.context = context
        self.publishers = publishers

    @property
    def tokens(self) -> TokenChecker:
        return self.context.tokens

    async def run(
        self, method: str, path: str, query: str, headers: Mapping[str, str], body: Any
    ) -> Reply:
        """The answer to ``method path?query`` (``headers`` with lower-case names, ``body``
        parsed JSON or None), as the REST app would give it."""
        try:
            reply = await self._run(method, path, query, headers, body)
        except ANSWERED_ERRORS as exc:
            answer = error_status(exc)
            assert answer is not None  # every answered error has a status
            status, detail = answer
            extra = exc.headers if isinstance(exc, ApiError) and exc.headers else {}
            return Reply(status, _encode({"detail": detail}), {**JSON, **_lower(extra)})
        if reply.body and "content-type" not in reply.headers:
            reply.headers.update(JSON)
        return reply

    async def _run(
        self, method: str, path: str, query: str, headers: Mapping[str, str], body: Any
    ) -> Reply:
        context = self.context
        query_values = dict(parse_qsl(query, keep_blank_values=True))
        token = token_from(headers, query_values, {})
        if token:
            role, refusal = context.guards.admit_token(self.tokens, ZENOH_ADDRESS, token)
            if refusal is not None:
                return _refused(refusal)
            if role is not None and (refusal := context.guards.admit_call(role, method)):
                return _refused(refusal)
        found = None
        if path.startswith(VEHICLES_PREFIX):
            found = match(method, path.removeprefix(VEHICLES_PREFIX))
        if found is None:
            reason = f"the edge runs the calls under {VEHICLES_PREFIX}{{id}} only, not {path}"
            raise ApiError(404, reason[:300], field="path")
        if found.call is None:
            return Reply(405, _encode({"detail": "Method Not Allowed"}), dict(JSON))
        call = found.call
        role = role_of(context, token)
        if call.access in (Access.PILOT, Access.CONTROL):
            pilot_only(context, role)
        errors: list[dict[str, Any]] = []
        vehicle_id = _vehicle_id(found.vehicle_id, errors)
        if vehicle_id is None:  # REST answers every input error at once
            errors += validate(call, body, query_values, found.params)[3]
            return _invalid(errors)
        vehicle = known_vehicle(context, vehicle_id)
        lease_id = headers.get("x-lease-id")
        checked = validate(call, body, query_values, found.params)
        if call.access is Access.CONTROL:
            # the call renews the lease, and it cannot lapse while the call runs; a refused
            # lease is answered only for a valid input (as REST: server/http/contract.py)
            try:
                with context.leases.hold(vehicle.sysid, lease_id):
                    require_connected(vehicle)
                    return await self._call(call, vehicle, lease_id, checked)
            except LeaseInvalid:
                if checked[3]:
                    return _invalid(checked[3])
                raise
        if call.access is Access.CONNECTED:
            require_connected(vehicle)
        return await self._call(call, vehicle, lease_id, checked)

    async def _call(
        self,
        call: VehicleCall,
        vehicle: Vehicle,
        lease_id: str | None,
        checked: tuple[Any, dict[str, Any], dict[str, Any], list[dict[str, Any]]],
    ) -> Reply:
        value, query_values, path_values, errors = checked
        if errors:
            return _invalid(errors)
        args = CallArgs(
            self.context, self.publishers, vehicle, lease_id, ZENOH_CLIENT,
            value, query_values, path_values,
        )  # fmt: skip
        return await call.run(args)


def _vehicle_id(raw: str, errors: list[dict[str, Any]]) -> int | None:
    value: int | None = validated(VEHICLE_ID.adapter, raw, ("path", "vehicle_id"), errors)
    return value


def _invalid(errors: list[dict[str, Any]]) -> Reply:
    return Reply(422, _encode({"detail": validation_detail(errors)}), dict(JSON))


def _refused(refusal: Refusal) -> Reply:
    body = refusal_body(refusal.reason, refusal.retry_after_s)
    headers = {**JSON, "retry-after": retry_after_header(refusal.retry_after_s)}
    return Reply(refusal.status, body, headers)


def _lower(headers: Mapping[str, str]) -> dict[str, str]:
    return {name.lower(): value for name, value in headers.items()}


def _encode(value: Any) -> bytes:
    return json.dumps(value, allow_nan=False).encode()
