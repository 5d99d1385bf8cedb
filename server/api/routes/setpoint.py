"""The offboard setpoint: checked (envelope, what PX4 accepts), sent now, then streamed."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body

from server.api.deps import ControlledVehicle
from server.api.errors import CONTROL_RESPONSES
from server.api.schemas import SentSetpointOut, SetpointBody, setpoint_body
from server.link import SentSetpoint

router = APIRouter(prefix="/vehicles/{vehicle_id}", tags=["setpoint"])


def sent_out(sent: SentSetpoint) -> SentSetpointOut:
    return SentSetpointOut(
        setpoint=setpoint_body(sent.setpoint),
        message=sent.message,
        frame=sent.frame,
        type_mask=sent.type_mask,
    )


@router.put("/setpoint", response_model=SentSetpointOut, responses=CONTROL_RESPONSES)
async def put_setpoint(
    vehicle: ControlledVehicle, body: Annotated[SetpointBody, Body()]
) -> SentSetpointOut:
    """Replace the streamed setpoint. Refused with 422 (field, reason, limit) when it breaks
    the envelope or is a combination PX4 would drop for this vehicle type."""
    return sent_out(await vehicle.set_setpoint(body.to_link()))
