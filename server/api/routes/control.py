"""The control lease over REST: acquire (or take over, asking the holder first or forcing it),
renew, inspect, answer a takeover request, release; and the audit log of control events."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import APIRouter, Body, Depends, Query, Request, Response

from server.control import lease_ops
from server.http.context import ApiContext
from server.http.deps import Context, KnownVehicle, LeaseIdHeader, Pilot, Reader
from server.http.errors import CONTROL_RESPONSES, READ_RESPONSES
from server.http.routing import route
from server.http.schemas import ErrorOut
from server.link import Vehicle
from skyhelm_wire.calls import API_PREFIX, AUDIT_LIMIT_MAX, CALL
from skyhelm_wire.control import (
    ControlBody,
    ControlStatusOut,
    LeaseOut,
    RenewBody,
    TakeoverAnswerBody,
    TakeoverAnswerOut,
)

router = APIRouter(prefix=API_PREFIX, tags=["control"])
DISCONNECT_POLL_S = 0.1
_REFUSED: dict[int | str, dict[str, Any]] = {
    409: {"model": ErrorOut, "description": "held by another, or the takeover refused"}
}


@dataclass
class _LeaseCall:
    """What every lease change needs: the pilot's vehicle, the context, the caller's lease id."""

    vehicle: Vehicle
    context: ApiContext
    lease_id: str | None


async def _lease_call(
    _: Pilot, vehicle: KnownVehicle, context: Context, x_lease_id: LeaseIdHeader = None
) -> _LeaseCall:
    return _LeaseCall(vehicle, context, x_lease_id)


LeaseCall = Annotated[_LeaseCall, Depends(_lease_call)]


async def _request_gone(request: Request) -> None:
    # HTTP has no disconnect event to wait on: look at the connection now and then
    while True:
        if await request.is_disconnected():
            return
        await asyncio.sleep(DISCONNECT_POLL_S)


@route(router, CALL["audit"], responses=READ_RESPONSES)
async def control_audit(
    context: Context,
    _: Reader,
    vehicle: Annotated[int | None, Query(ge=0, le=255, description="one vehicle's only")] = None,
    limit: Annotated[int, Query(ge=1, le=AUDIT_LIMIT_MAX)] = 100,
) -> list[dict[str, Any]]:
    """The newest control and deadman events, oldest first; kept across restarts in
    `<log_dir>/control-audit.jsonl`."""
    return context.audit.entries(vehicle, limit)


@route(router, CALL["acquire"], responses={**CONTROL_RESPONSES, **_REFUSED})
async def acquire_control(
    request: Request, call: LeaseCall, body: Annotated[ControlBody | None, Body()] = None
) -> LeaseOut:
    """Take the control lease (409 while another pilot holds it). With `takeover` the
    holder is asked first and has takeover_ask_s to grant it (409 when denied or
    unanswered); with `takeover` and `force` it is taken at once. Sending the current
    X-Lease-Id renews it instead."""
    context = call.context
    client = request.client
    return await lease_ops.acquire(
        context.leases, call.vehicle, body or ControlBody(), call.lease_id,
        pilot=context.pilot_name, client=(client.host, client.port) if client else None,
        ask_s=context.settings.takeover_ask_s, gone=lambda: _request_gone(request),
    )


@route(router, CALL["renew"], responses=CONTROL_RESPONSES)
async def renew_control(
    call: LeaseCall, body: Annotated[RenewBody | None, Body()] = None
) -> LeaseOut:
    """Renew the lease; optionally change its TTL and the client's label."""
    context = call.context
    return lease_ops.renew(
        context.leases, call.vehicle, body or RenewBody(), call.lease_id,
        pilot=context.pilot_name,
    )


@route(router, CALL["control_status"], responses=READ_RESPONSES)
async def control_status(vehicle: KnownVehicle, context: Context, _: Reader) -> ControlStatusOut:
    """Who holds control, since when, until when, and a pending takeover request."""
    return lease_ops.status(context.leases, vehicle.sysid)


@route(router, CALL["release"], status_code=204, response_class=Response,
       responses=CONTROL_RESPONSES)
async def release_control(call: LeaseCall) -> Response:
    """Give control back. While the streamer runs, this applies on_operator_loss."""
    lease_ops.release(call.context.leases, call.vehicle, call.lease_id)
    return Response(status_code=204)


@route(
    router,
    CALL["answer_takeover"],
    responses={**CONTROL_RESPONSES, 404: {"model": ErrorOut, "description": "no such request"}},
)
async def answer_takeover(
    request_id: str, body: TakeoverAnswerBody, call: LeaseCall
) -> TakeoverAnswerOut:
    """The holder grants or denies a takeover request (its X-Lease-Id proves it holds it)."""
    return lease_ops.answer_takeover(
        call.context.leases, call.vehicle, call.lease_id, request_id, body
    )
