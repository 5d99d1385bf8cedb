"""Intents: what the pilot means, decided in the server (``server.link.intents``) so that
the page, scripts and the control socket fly the same way and meet the same checks.

Each answers ``IntentOut``: the setpoint it streams, or the vehicle's answer to the command
it sent (then with that command's status: 409 refused, 504 no answer). Moves outside the
envelope are a 422 naming the input and the limit, before anything is sent."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse
from pydantic import BaseModel

from server.control import operations
from server.http.deps import Context, ControlledVehicle
from server.http.errors import COMMAND_RESPONSES, command_status
from server.http.routing import route
from server.link import Vehicle
from skyhelm_wire.calls import CALL
from skyhelm_wire.intents import GotoIntentBody, OffsetIntentBody, VelocityIntentBody

router = APIRouter(tags=["intents"], responses=COMMAND_RESPONSES)


async def answer_intent(
    context: Context, vehicle: Vehicle, name: str, body: BaseModel | None
) -> JSONResponse:
    answer = await operations.answer_intent(context.deadman, vehicle, name, body)
    return JSONResponse(answer.body, status_code=command_status(answer.outcome))


@route(router, CALL["brake"])
async def brake(vehicle: ControlledVehicle, context: Context) -> JSONResponse:
    """Stop and hold where the vehicle stops. Streaming setpoints: a zero velocity, then a
    position hold once it is slow (events `intent` braking / holding). Otherwise HOLD mode,
    in which PX4 brakes and holds by itself."""
    return await answer_intent(context, vehicle, "brake", None)


@route(router, CALL["velocity"])
async def velocity(
    vehicle: ControlledVehicle, context: Context, body: VelocityIntentBody
) -> JSONResponse:
    """Fly at a velocity (body: forward/right, ned: north/east; up_m_s; yaw_rate_deg_s),
    streamed as an offboard setpoint. Live unless `live` is false: without a new call within
    the deadman timeout the vehicle brakes and holds. With hold_altitude the altitude of the
    first such call is held instead of a vertical speed."""
    return await answer_intent(context, vehicle, "velocity", body)


@route(router, CALL["offset"])
async def offset(
    vehicle: ControlledVehicle, context: Context, body: OffsetIntentBody
) -> JSONResponse:
    """Go by north_m/east_m/up_m from where the vehicle is (the point computed on WGS-84).
    In OFFBOARD as a position setpoint; in any other mode as MAV_CMD_DO_REPOSITION."""
    return await answer_intent(context, vehicle, "offset", body)


@route(router, CALL["goto"])
async def goto(vehicle: ControlledVehicle, context: Context, body: GotoIntentBody) -> JSONResponse:
    """Go to lat_deg/lon_deg at alt_rel_m above home (default: the current altitude). In
    OFFBOARD as a global position setpoint; in any other mode as MAV_CMD_DO_REPOSITION."""
    return await answer_intent(context, vehicle, "goto", body)
