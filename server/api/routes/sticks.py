"""Manual control from a script: the same sticks the page sends over the control socket.

Sticks are live input: the server keeps sending them at 25 Hz, and unless new sticks come
within deadman_timeout_s it centres them, then stops sending (PX4's own manual control loss
failsafe then applies). Starting sticks stops the offboard setpoint stream and the other way
round."""

from __future__ import annotations

from fastapi import APIRouter

from server.control.vehicle_ops import fly_sticks, sticks_out, stop_sticks
from server.http.deps import Context, ControlledVehicle, KnownVehicle
from server.http.errors import CONTROL_RESPONSES, READ_RESPONSES
from server.http.routing import route
from skyhelm_wire.calls import API_PREFIX, CALL
from skyhelm_wire.sticks import SticksBody, SticksOut

router = APIRouter(prefix=API_PREFIX, tags=["sticks"])


@route(router, CALL["sticks"], responses=READ_RESPONSES)
async def get_sticks(vehicle: KnownVehicle) -> SticksOut:
    """The sticks being sent and the stream's figures."""
    return sticks_out(vehicle)


@route(router, CALL["fly_sticks"], responses=CONTROL_RESPONSES)
async def put_sticks(vehicle: ControlledVehicle, context: Context, body: SticksBody) -> SticksOut:
    """Fly with these sticks (MANUAL_CONTROL at 25 Hz). Live: send again within
    deadman_timeout_s, or the sticks are centred and then no longer sent."""
    return fly_sticks(context.deadman, vehicle, body)


@route(router, CALL["stop_sticks"], responses=CONTROL_RESPONSES)
async def delete_sticks(vehicle: ControlledVehicle, context: Context) -> SticksOut:
    """Stop sending MANUAL_CONTROL (PX4 sees manual control lost after COM_RC_LOSS_T)."""
    return stop_sticks(context.deadman, vehicle)
