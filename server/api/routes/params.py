"""Vehicle parameters: read some, read all, read one, set one (echo-checked)."""

from __future__ import annotations

import re
from typing import Annotated

from fastapi import APIRouter, Path, Query

from server.control.views import finite
from server.http.deps import ConnectedVehicle, ControlledVehicle
from server.http.errors import CONTROL_RESPONSES, READ_RESPONSES, ApiError, Responses
from server.http.schemas import ErrorOut, ParamOut, ParamsOut, ParamValueBody

router = APIRouter(prefix="/vehicles/{vehicle_id}/params", tags=["params"])

# PX4 parameter ids are at most 16 characters.
_NAME = re.compile(r"[A-Za-z0-9_]{1,16}")
ParamName = Annotated[str, Path(pattern=r"^[A-Za-z0-9_]{1,16}$", examples=["MIS_TAKEOFF_ALT"])]
_NO_ANSWER: Responses = {
    504: {"model": ErrorOut, "description": "no answer (PX4 ignores unknown names)"}
}
_REFUSED: Responses = {
    409: {"model": ErrorOut, "description": "the vehicle refused or kept another value"}
}
_LOST: Responses = {503: {"model": ErrorOut, "description": "the vehicle is not connected"}}
_READ: Responses = {**READ_RESPONSES, **_LOST, **_NO_ANSWER, **_REFUSED}


def _names(names: str | None) -> list[str] | None:
    if names is None:
        return None
    wanted = [name.strip() for name in names.split(",") if name.strip()]
    for name in wanted:
        if len(name) > 16:
            raise ApiError(422, f"parameter name {name!r} is longer than 16", field="names")
        if _NAME.fullmatch(name) is None:
            # the same rule as a single name in the path: PX4's ids are ASCII
            raise ApiError(422, f"parameter name {name!r} is not [A-Za-z0-9_]", field="names")
    return wanted


@router.get("", response_model=ParamsOut, responses=_READ)
async def get_params(
    vehicle: ConnectedVehicle,
    names: Annotated[str | None, Query(description="comma-separated; omit for all")] = None,
) -> ParamsOut:
    return ParamsOut(params=finite(await vehicle.get_params(_names(names))))


@router.get("/{name}", response_model=ParamOut, responses=_READ)
async def get_param(vehicle: ConnectedVehicle, name: ParamName) -> ParamOut:
    return ParamOut(name=name, value=finite(await vehicle.get_param(name)))


@router.put(
    "/{name}", response_model=ParamOut, responses={**CONTROL_RESPONSES, **_NO_ANSWER, **_REFUSED}
)
async def set_param(vehicle: ControlledVehicle, name: ParamName, body: ParamValueBody) -> ParamOut:
    return ParamOut(name=name, value=finite(await vehicle.set_param(name, body.value)))
