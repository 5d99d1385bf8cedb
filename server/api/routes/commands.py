"""Vehicle commands. Each answers with the vehicle's real result: 200 ACCEPTED, 409 refused
(MAV_RESULT and the vehicle's reason), 504 no answer, 503 link lost.

There is one route per operation of :data:`server.control.operations.OPERATIONS`, taking that
operation's body: the WebSocket control session runs the same table, so both refuse and
answer alike. A body whose fields all have defaults may be left out."""

from __future__ import annotations

import inspect
from collections.abc import Awaitable, Callable

from fastapi import APIRouter
from fastapi.responses import JSONResponse
from pydantic import BaseModel

from server.control.operations import OPERATIONS, run_command
from server.http.deps import ControlledVehicle
from server.http.error_handlers import command_response
from server.http.errors import COMMAND_RESPONSES
from server.http.routing import body_parameter, route_options
from server.link import Vehicle
from skyhelm_wire.calls import API_PREFIX, CALL

router = APIRouter(prefix=API_PREFIX, tags=["commands"], responses=COMMAND_RESPONSES)

async def run_operation(name: str, vehicle: Vehicle, body: BaseModel | None) -> JSONResponse:
    return command_response(await run_command(name, vehicle, body))


_Endpoint = Callable[..., Awaitable[JSONResponse]]


def _endpoint(name: str, route_name: str, doc: str | None) -> _Endpoint:
    async def endpoint(vehicle: Vehicle, body: BaseModel | None = None) -> JSONResponse:
        return await run_operation(name, vehicle, body)

    parameters = [
        inspect.Parameter(
            "vehicle", inspect.Parameter.POSITIONAL_OR_KEYWORD, annotation=ControlledVehicle
        )
    ]
    body = body_parameter(CALL[name])
    if body is not None:
        parameters.append(body)
    # FastAPI reads a route's parameters from its signature: this one is built from the table.
    endpoint.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
        parameters, return_annotation=JSONResponse
    )
    endpoint.__name__ = endpoint.__qualname__ = route_name
    endpoint.__doc__ = doc
    return endpoint


def _add_routes() -> None:
    """One route per operation, at the wire's method and path, named and described by the
    operation's function."""
    for name, operation in OPERATIONS.items():
        call = CALL[name]
        endpoint = _endpoint(name, operation.run.__name__, operation.run.__doc__)
        router.add_api_route(call.route, endpoint, **route_options(call, {}))


_add_routes()
