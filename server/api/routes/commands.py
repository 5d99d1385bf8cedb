"""Vehicle commands. Each answers with the vehicle's real result: 200 ACCEPTED, 409 refused
(MAV_RESULT and the vehicle's reason), 504 no answer, 503 link lost."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body
from fastapi.responses import JSONResponse
from pydantic import BaseModel

from server.api.deps import ControlledVehicle
from server.api.errors import COMMAND_RESPONSES, command_response
from server.api.operations import OPERATIONS
from server.api.schemas import (
    ArmBody,
    CommandResultOut,
    HomeBody,
    ModeBody,
    OffboardStartBody,
    OffboardStopBody,
    OriginBody,
    RepositionBody,
    TakeoffBody,
    VtolTransitionBody,
)
from server.link import Vehicle

router = APIRouter(
    prefix="/vehicles/{vehicle_id}",
    tags=["commands"],
    responses=COMMAND_RESPONSES,
)


async def run_operation(name: str, vehicle: Vehicle, body: BaseModel | None) -> JSONResponse:
    operation = OPERATIONS[name]
    result = await operation.run(vehicle, body if body is not None else operation.body())
    return command_response(result)


@router.post("/arm", response_model=CommandResultOut)
async def arm(
    vehicle: ControlledVehicle, body: Annotated[ArmBody | None, Body()] = None
) -> JSONResponse:
    return await run_operation("arm", vehicle, body)


@router.post("/disarm", response_model=CommandResultOut)
async def disarm(
    vehicle: ControlledVehicle, body: Annotated[ArmBody | None, Body()] = None
) -> JSONResponse:
    """Without force PX4 refuses unless landed ("Disarming denied: not landed")."""
    return await run_operation("disarm", vehicle, body)


@router.post("/takeoff", response_model=CommandResultOut)
async def takeoff(
    vehicle: ControlledVehicle, body: Annotated[TakeoffBody | None, Body()] = None
) -> JSONResponse:
    """Climb to altitude_m above home (default: the vehicle's MIS_TAKEOFF_ALT)."""
    return await run_operation("takeoff", vehicle, body)


@router.post("/land", response_model=CommandResultOut)
async def land(vehicle: ControlledVehicle) -> JSONResponse:
    return await run_operation("land", vehicle, None)


@router.post("/rtl", response_model=CommandResultOut)
async def rtl(vehicle: ControlledVehicle) -> JSONResponse:
    return await run_operation("rtl", vehicle, None)


@router.post("/hold", response_model=CommandResultOut)
async def hold(vehicle: ControlledVehicle) -> JSONResponse:
    return await run_operation("hold", vehicle, None)


@router.post("/mode", response_model=CommandResultOut)
async def set_mode(vehicle: ControlledVehicle, body: ModeBody) -> JSONResponse:
    """Resolves when the vehicle reports the mode (or says why not)."""
    return await run_operation("mode", vehicle, body)


@router.post("/reposition", response_model=CommandResultOut)
async def reposition(vehicle: ControlledVehicle, body: RepositionBody) -> JSONResponse:
    """MAV_CMD_DO_REPOSITION: fly there and hold (ends OFFBOARD)."""
    return await run_operation("reposition", vehicle, body)


@router.post("/vtol/transition", response_model=CommandResultOut)
async def vtol_transition(vehicle: ControlledVehicle, body: VtolTransitionBody) -> JSONResponse:
    """With wait, resolves when EXTENDED_SYS_STATE shows the new VTOL state."""
    return await run_operation("vtol_transition", vehicle, body)


@router.post("/origin", response_model=CommandResultOut)
async def set_origin(vehicle: ControlledVehicle, body: OriginBody) -> JSONResponse:
    """SET_GPS_GLOBAL_ORIGIN, confirmed by the GPS_GLOBAL_ORIGIN the vehicle sends back."""
    return await run_operation("origin", vehicle, body)


@router.post("/home", response_model=CommandResultOut)
async def set_home(
    vehicle: ControlledVehicle, body: Annotated[HomeBody | None, Body()] = None
) -> JSONResponse:
    """MAV_CMD_DO_SET_HOME at the given point, or at the current position without a body."""
    return await run_operation("home", vehicle, body)


@router.post("/offboard/start", response_model=CommandResultOut)
async def offboard_start(
    vehicle: ControlledVehicle, body: Annotated[OffboardStartBody | None, Body()] = None
) -> JSONResponse:
    """Stream the setpoint (default: hold here) and switch to OFFBOARD; resolves when the
    vehicle reports OFFBOARD."""
    return await run_operation("offboard_start", vehicle, body)


@router.post("/offboard/stop", response_model=CommandResultOut)
async def offboard_stop(
    vehicle: ControlledVehicle, body: Annotated[OffboardStopBody | None, Body()] = None
) -> JSONResponse:
    """Switch to then_mode, then stop streaming."""
    return await run_operation("offboard_stop", vehicle, body)
