"""The control lease over REST: acquire (or take over), renew, inspect, release."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Request, Response

from server.api.deps import Context, KnownVehicle, LeaseIdHeader, Pilot, Reader
from server.api.errors import CONTROL_RESPONSES, READ_RESPONSES, ApiError
from server.api.lease import Lease, LeaseHeld
from server.api.schemas import ControlBody, ErrorOut, LeaseOut, LeaseStatusOut

router = APIRouter(prefix="/vehicles/{vehicle_id}/control", tags=["control"])


def lease_out(lease: Lease, context: Context) -> LeaseOut:
    _, expires_in_s = context.leases.status(lease.vehicle_id)
    return LeaseOut(
        lease_id=lease.lease_id,
        ttl_s=lease.ttl_s,
        holder=lease.holder,
        expires_in_s=expires_in_s if expires_in_s is not None else 0.0,
    )


def holder_name(request: Request, client_name: str | None) -> str:
    if client_name:
        return client_name
    client = request.client
    return f"pilot@{client.host}:{client.port}" if client else "pilot"


@router.post(
    "",
    response_model=LeaseOut,
    responses={**CONTROL_RESPONSES, 409: {"model": ErrorOut, "description": "held by another"}},
)
async def acquire_control(
    request: Request,
    _: Pilot,
    vehicle: KnownVehicle,
    context: Context,
    body: Annotated[ControlBody | None, Body()] = None,
    x_lease_id: LeaseIdHeader = None,
) -> LeaseOut:
    """Take the control lease (409 while another pilot holds it, unless `takeover`).
    Sending the current X-Lease-Id renews it instead."""
    body = body or ControlBody()
    try:
        lease = context.leases.acquire(
            vehicle.sysid,
            holder_name(request, body.client_name),
            session="rest",
            takeover=body.takeover,
            lease_id=x_lease_id,
        )
    except LeaseHeld as held:
        raise ApiError(409, str(held), holder=held.lease.holder) from None
    return lease_out(lease, context)


@router.put("", response_model=LeaseOut, responses=CONTROL_RESPONSES)
async def renew_control(
    _: Pilot, vehicle: KnownVehicle, context: Context, x_lease_id: LeaseIdHeader = None
) -> LeaseOut:
    return lease_out(context.leases.renew(vehicle.sysid, x_lease_id), context)


@router.get("", response_model=LeaseStatusOut, responses=READ_RESPONSES)
async def control_status(vehicle: KnownVehicle, context: Context, _: Reader) -> LeaseStatusOut:
    holder, expires_in_s = context.leases.status(vehicle.sysid)
    return LeaseStatusOut(holder=holder, expires_in_s=expires_in_s)


@router.delete("", status_code=204, response_class=Response, responses=CONTROL_RESPONSES)
async def release_control(
    _: Pilot, vehicle: KnownVehicle, context: Context, x_lease_id: LeaseIdHeader = None
) -> Response:
    """Give control back. While the streamer runs, this applies on_operator_loss."""
    context.leases.release(vehicle.sysid, x_lease_id)
    return Response(status_code=204)
