"""The fleet's REST routes on a server started with ``--fleet`` (docs/api.md, "Fleet").

Reads come from the fleet view (what the edges published); everything else under a fleet
vehicle is one REST call run by its edge (proxy.py) with the caller's token and lease, so
the edge decides exactly as its own REST would. This server checks the token too: an
observer may read here and never fly.
"""

from __future__ import annotations

import json
from typing import Annotated, Any
from urllib.parse import urlencode

from fastapi import APIRouter, Path, Request, Response
from fastapi.responses import JSONResponse

from server.control.auth import TOKEN_QUERY, Role, token_from
from server.fleet.proxy import EdgeReplyError, EdgeTimeout, call_timeout_s, edge_call
from server.fleet.view_service import FleetService
from server.http.deps import Reader, VehicleId
from server.http.errors import (
    AUTH_RESPONSES,
    CONTROL_RESPONSES,
    READ_RESPONSES,
    ApiError,
    refuse_non_finite,
)
from server.http.routing import route
from server.http.schemas import ErrorOut
from skyhelm_wire.calls import API_PREFIX, CALL, FLEET_VEHICLE_PATH, VEHICLE_CALLS, VEHICLE_PATH
from skyhelm_wire.fleet import FLEET_NAME_PATTERN

router = APIRouter(prefix=API_PREFIX, tags=["fleet"])

EdgeName = Annotated[
    str, Path(pattern=FLEET_NAME_PATTERN, description="the edge's name in the fleet")
]
# the methods of the vehicle's calls, each proxied to the vehicle's edge
PROXIED_METHODS = list(dict.fromkeys(call.method for call in VEHICLE_CALLS))
# the edge's answer headers a caller may act on
PASSED_HEADERS = ("retry-after", "www-authenticate", "location")

PROXY_RESPONSES: dict[int | str, dict[str, Any]] = {
    **CONTROL_RESPONSES,
    502: {"model": ErrorOut, "description": "the edge answered with a Zenoh error"},
    503: {"model": ErrorOut, "description": "the edge is not alive (lost)"},
    504: {"model": ErrorOut, "description": "the edge did not answer within 5 s (a read), "
          "15 s (a command), takeover_ask_s + 15 s (an ask for control)"},
}


def fleet_of(request: Request) -> FleetService:
    service: FleetService = request.app.state.fleet
    return service


@route(router, CALL["fleet"], responses=AUTH_RESPONSES)
async def get_fleet(request: Request, _: Reader) -> dict[str, Any]:
    """The fleet's edges, alive or lost, with their vehicles' ids."""
    return fleet_of(request).view.summary()


@route(router, CALL["fleet_vehicles"], responses=AUTH_RESPONSES)
async def list_fleet_vehicles(request: Request, _: Reader) -> list[dict[str, Any]]:
    """Every vehicle heard from, with its freshness and who controls it."""
    return [vehicle.summary() for vehicle in fleet_of(request).view.vehicles()]


@route(
    router,
    CALL["fleet_vehicle"],
    responses={**READ_RESPONSES, 200: {"description": "GET /vehicles/{id} of its edge, "
                                       "plus edge, id, key, alive, age_s, state_age_s"}},
)
async def get_fleet_vehicle(
    request: Request, edge: EdgeName, vehicle_id: VehicleId, _: Reader
) -> dict[str, Any]:
    """The vehicle's last state as its edge published it, and the fleet's fields."""
    vehicle = fleet_of(request).view.vehicle(edge, vehicle_id)
    if vehicle is None:
        raise ApiError(404, f"no vehicle {edge}/{vehicle_id} in the fleet")
    return vehicle.detail()


async def call_fleet_vehicle(
    request: Request, edge: EdgeName, vehicle_id: VehicleId, rest: str, role: Reader
) -> Response:
    """`/api/v1/vehicles/{vehicle_id}/{rest}` run by the vehicle's edge with the caller's
    token and X-Lease-Id: the edge's status, body and Retry-After, verbatim."""
    if request.method != "GET" and role is not Role.PILOT:
        raise ApiError(403, "observer tokens may only read; this call needs the pilot token")
    segments = rest.split("/")
    if not rest or any(part in ("", ".", "..") for part in segments):
        raise ApiError(422, "not a path under the vehicle", field="rest")
    service = fleet_of(request)
    owner = service.view.edge(edge)
    if owner is None:
        raise ApiError(404, f"no edge {edge} in the fleet")
    if not owner.alive or service.session is None:
        raise ApiError(503, f"edge {edge} is not alive")
    call = {
        "method": request.method,
        "path": f"{API_PREFIX}{VEHICLE_PATH.format(vehicle_id=vehicle_id)}/{rest}",
        "query": _query_without_token(request),
        "headers": _forwarded_headers(request),
        "body": await _json_body(request),
    }
    timeout_s = call_timeout_s(
        request.method, rest, call["body"], service.takeover_ask_s, service.query_timeout_s
    )
    try:
        answer = await edge_call(service.session, service.keys, edge, call, timeout_s)
    except EdgeTimeout as exc:
        raise ApiError(504, str(exc)) from None
    except EdgeReplyError as exc:
        raise ApiError(502, f"edge {edge}: {exc}") from None
    headers = {name: answer.headers[name] for name in PASSED_HEADERS if name in answer.headers}
    if answer.body is None and answer.status in (204, 304):
        return Response(status_code=answer.status, headers=headers)
    return JSONResponse(answer.body, status_code=answer.status, headers=headers)


# every call of a fleet vehicle (the wire's vehicle calls) is run by its edge: one route per
# method, so that each is its own operation in OpenAPI
for _method in PROXIED_METHODS:
    router.add_api_route(
        f"{FLEET_VEHICLE_PATH}/{{rest:path}}", call_fleet_vehicle, methods=[_method],
        responses=PROXY_RESPONSES,
    )  # fmt: skip


def _forwarded_headers(request: Request) -> dict[str, str]:
    """Only the caller's authority goes to the edge: its token (from whichever place it
    came in) and its lease."""
    headers: dict[str, str] = {}
    token = token_from(request.headers, request.query_params, request.cookies)
    if token:
        headers["authorization"] = f"Bearer {token}"
    lease = request.headers.get("x-lease-id")
    if lease is not None:
        headers["x-lease-id"] = lease
    return headers


def _query_without_token(request: Request) -> str | None:
    items = [(k, v) for k, v in request.query_params.multi_items() if k != TOKEN_QUERY]
    if not items:
        return None
    return urlencode(items)


async def _json_body(request: Request) -> Any:
    raw = await request.body()
    if not raw.strip():
        return None
    try:
        body = json.loads(raw)
    except ValueError:
        raise ApiError(422, "the body is not JSON", field="body") from None
    refuse_non_finite(body)
    return body
