"""The offboard setpoint: checked (envelope, what PX4 accepts), sent now, then streamed."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Query

from server.control.deadman import LIVE_DESCRIPTION
from server.control.vehicle_ops import put_setpoint as put_setpoint_of
from server.http.deps import Context, ControlledVehicle
from server.http.errors import CONTROL_RESPONSES
from server.http.routing import route
from server.http.schemas import SentSetpointOut, SetpointBody
from skyhelm_wire.calls import API_PREFIX, CALL

router = APIRouter(prefix=API_PREFIX, tags=["setpoint"])


@route(router, CALL["set_setpoint"], responses=CONTROL_RESPONSES)
async def put_setpoint(
    vehicle: ControlledVehicle,
    context: Context,
    body: Annotated[SetpointBody, Body()],
    live: Annotated[bool, Query(description=LIVE_DESCRIPTION)] = False,
) -> SentSetpointOut:
    """Replace the streamed setpoint. Refused with 422 (field, reason, limit) when it breaks
    the envelope or is a combination PX4 would drop for this vehicle type."""
    return await put_setpoint_of(context.deadman, vehicle, body, live=live)
