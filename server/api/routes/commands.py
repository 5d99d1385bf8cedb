"""Vehicle commands. Each answers with the vehicle's real result: 200 ACCEPTED, 409 refused
(MAV_RESULT and the vehicle's reason), 504 no answer, 503 link lost.

There is one route per operation of :data:`server.control.operations.OPERATIONS`, taking that
operation's body: the WebSocket control session runs the same table, so both refuse and
answer alike. A body whose fields all have defaults may be left out."""

from __future__ import annotations

import inspect
from collections.abc import Awaitable, Callable
from typing import Annotated

from fastapi import APIRouter, Body
from fastapi.responses import JSONResponse
from pydantic import BaseModel

from server.control.operations import OPERATIONS, run_command
from server.http.deps import ControlledVehicle
from server.http.error_handlers import command_response
from server.http.errors import COMMAND_RESPONSES
from server.link import Vehicle
from skyhelm_wire.calls import CALL

router = APIRouter(
    prefix="/vehicles/{vehicle_id}",
    tags=["commands"],
    responses=COMMAND_RESPONSES,
)

# (operation, route name (it names the OpenAPI operationId), what the route documents); the
# method and path are the wire's (skyhelm_wire.calls)
_ROUTES: tuple[tuple[str, str, str | None], ...] = (
    ("arm", "arm", None),
    ("disarm", "disarm",
     'Without force PX4 refuses unless landed ("Disarming denied: not landed").'),
    ("takeoff", "takeoff",
     "Climb to altitude_m above home (default: the vehicle's MIS_TAKEOFF_ALT); above the\n"
     "envelope's max_alt_rel_m: 422."),
    ("land", "land", None),
    ("rtl", "rtl", None),
    ("hold", "hold", None),
    ("mode", "set_mode", "Resolves when the vehicle reports the mode (or says why not)."),
    ("reposition", "reposition",
     "MAV_CMD_DO_REPOSITION: fly there and hold (ends OFFBOARD). Outside the envelope: 422\n"
     "naming the field and the limit. The goto intent picks this or a setpoint by mode."),
    ("vtol_transition", "vtol_transition",
     "With wait, resolves when EXTENDED_SYS_STATE shows the new VTOL state."),
    ("origin", "set_origin",
     "SET_GPS_GLOBAL_ORIGIN, confirmed by the GPS_GLOBAL_ORIGIN the vehicle sends back."),
    ("home", "set_home",
     "MAV_CMD_DO_SET_HOME at the given point, or at the current position without a body."),
    ("offboard_start", "offboard_start",
     "Stream the setpoint (default: hold here) and switch to OFFBOARD; resolves when the\n"
     "vehicle reports OFFBOARD."),
    ("offboard_stop", "offboard_stop",
     "Switch to then_mode, then stop streaming."),
)


async def run_operation(name: str, vehicle: Vehicle, body: BaseModel | None) -> JSONResponse:
    return command_response(await run_command(name, vehicle, body))


def _body_parameter(model: type[BaseModel]) -> inspect.Parameter | None:
    """The route's body: none for an empty model, optional when every field has a default."""
    if not model.model_fields:
        return None
    if any(field.is_required() for field in model.model_fields.values()):
        return inspect.Parameter("body", inspect.Parameter.KEYWORD_ONLY, annotation=model)
    return inspect.Parameter(
        "body",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=Annotated[model | None, Body()],
        default=None,
    )


_Endpoint = Callable[..., Awaitable[JSONResponse]]


def _endpoint(name: str, route_name: str, doc: str | None) -> _Endpoint:
    async def endpoint(vehicle: Vehicle, body: BaseModel | None = None) -> JSONResponse:
        return await run_operation(name, vehicle, body)

    parameters = [
        inspect.Parameter(
            "vehicle", inspect.Parameter.POSITIONAL_OR_KEYWORD, annotation=ControlledVehicle
        )
    ]
    body = _body_parameter(OPERATIONS[name].body)
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
    for name, route_name, doc in _ROUTES:
        call = CALL[name]
        router.add_api_route(
            f"/{call.path}", _endpoint(name, route_name, doc), methods=[call.method],
            response_model=call.answer,
        )


_add_routes()
