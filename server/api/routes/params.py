"""Vehicle parameters: read some, read all, read one, set one (echo-checked)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Query

from server.control import vehicle_ops
from server.http.deps import ConnectedVehicle, ControlledVehicle
from server.http.errors import CONTROL_RESPONSES, READ_RESPONSES, Responses
from server.http.routing import route
from server.http.schemas import ErrorOut, ParamMetadataOut, ParamOut, ParamsOut, ParamValueBody
from skyhelm_wire.calls import (
    API_PREFIX,
    CALL,
    PARAM_NAME_LENGTH,
    PARAM_NAME_PATTERN,
    PARAM_NAMES_PATTERN,
)

router = APIRouter(prefix=API_PREFIX, tags=["params"])

ParamName = Annotated[
    str,
    Path(
        pattern=PARAM_NAME_PATTERN, min_length=1, max_length=PARAM_NAME_LENGTH,
        examples=["MIS_TAKEOFF_ALT"],
    ),
]  # fmt: skip
ParamNames = Annotated[
    str | None,
    Query(
        pattern=PARAM_NAMES_PATTERN,
        description="comma-separated, each as a parameter's name; omit for all",
        examples=["MIS_TAKEOFF_ALT,MPC_XY_VEL_MAX"],
    ),
]
_NO_ANSWER: Responses = {
    404: {"model": ErrorOut, "description": "no such vehicle, or no such parameter on it"},
    504: {"model": ErrorOut, "description": "no answer from the vehicle"},
}
_REFUSED: Responses = {
    409: {"model": ErrorOut, "description": "the vehicle refused or kept another value"}
}
_LOST: Responses = {503: {"model": ErrorOut, "description": "the vehicle is not connected"}}
_READ: Responses = {**READ_RESPONSES, **_LOST, **_NO_ANSWER, **_REFUSED}


@route(router, CALL["params"], responses=_READ)
async def get_params(
    vehicle: ConnectedVehicle,
    names: ParamNames = None,
) -> ParamsOut:
    return await vehicle_ops.get_params(vehicle, names)


@route(router, CALL["param_metadata"], responses=READ_RESPONSES)
async def get_param_metadata(vehicle: ConnectedVehicle) -> ParamMetadataOut:
    """What each parameter is (group, descriptions, units, range, default), from the
    component metadata the vehicle serves (PX4's parameters.json, read once over MAVLink FTP)."""
    return await vehicle_ops.get_param_metadata(vehicle)


@route(router, CALL["param"], responses=_READ)
async def get_param(vehicle: ConnectedVehicle, name: ParamName) -> ParamOut:
    return await vehicle_ops.get_param(vehicle, name)


@route(router, CALL["set_param"], responses={**CONTROL_RESPONSES, **_NO_ANSWER, **_REFUSED})
async def set_param(vehicle: ControlledVehicle, name: ParamName, body: ParamValueBody) -> ParamOut:
    """Set it and check the vehicle's echo. A value outside the range of the vehicle's
    metadata is 422 (field ``value``, ``minimum``, ``maximum``, ``units``, ``description``)
    unless the body says ``"force": true``."""
    return await vehicle_ops.set_param(vehicle, name, body)
