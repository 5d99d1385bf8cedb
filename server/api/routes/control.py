"""The control lease over REST: acquire (or take over, asking the holder first or forcing it),
renew, inspect, answer a takeover request, release; and the audit log of control events."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import APIRouter, Body, Depends, Query, Request, Response

from server.control.auth import same_secret
from server.control.holder_process import verified_holder
from server.control.lease import Lease, LeaseHeld, TakeoverRefused, TtlOutOfBounds, UnknownRequest
from server.http.deps import ApiContext, Context, KnownVehicle, LeaseIdHeader, Pilot, Reader
from server.http.errors import CONTROL_RESPONSES, READ_RESPONSES, ApiError
from server.http.schemas import ErrorOut, setpoint_body
from server.link import Vehicle
from skyhelm_wire.control import (
    AuditEntryOut,
    ControlBody,
    ControlStatusOut,
    LeaseEndOut,
    LeaseOut,
    RenewBody,
    TakeoverAnswerBody,
    TakeoverAnswerOut,
    TakeoverRequestOut,
)

router = APIRouter(tags=["control"])
_lease_router = APIRouter(prefix="/vehicles/{vehicle_id}/control")

AUDIT_LIMIT_MAX = 1000
DISCONNECT_POLL_S = 0.1
_REFUSED: dict[int | str, dict[str, Any]] = {
    409: {"model": ErrorOut, "description": "held by another, or the takeover refused"}
}


def lease_out(lease: Lease, context: ApiContext, vehicle: Vehicle | None) -> LeaseOut:
    """The lease as its holder sees it, with the setpoint being flown so it starts from it."""
    now = context.leases.now()
    flying = vehicle.offboard.setpoint if vehicle is not None and vehicle.streamer_active else None
    return LeaseOut(
        lease_id=lease.lease_id,
        holder=lease.holder,
        session="ws" if lease.session == "ws" else "rest",
        ttl_s=lease.ttl_s,
        expires_in_s=round(lease.expires_in_s(now), 3),
        since_s=round(max(0.0, now - lease.since), 3),
        setpoint=setpoint_body(flying) if flying is not None else None,
        taken_from=lease.taken_from,
    )


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


class AskerGone(Exception):
    """The client asking for control went away before the holder answered."""


async def unless_gone(asking: Awaitable[Lease], gone: Awaitable[None]) -> Lease:
    """The lease once the holder answers, or AskerGone (and the request withdrawn) when the
    asking client leaves first, so control is never handed to nobody."""
    answer = asyncio.ensure_future(asking)
    left = asyncio.ensure_future(gone)
    try:
        await asyncio.wait({answer, left}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        left.cancel()
        if not answer.done():
            answer.cancel()
        await asyncio.gather(answer, left, return_exceptions=True)
    if answer.cancelled():
        raise AskerGone
    return answer.result()


async def _request_gone(request: Request) -> None:
    # HTTP has no disconnect event to wait on: look at the connection now and then
    while True:
        if await request.is_disconnected():
            return
        await asyncio.sleep(DISCONNECT_POLL_S)


def ttl_checked(context: ApiContext, ttl_s: float | None) -> float:
    """The TTL to grant, or a 422 naming the bound it broke."""
    try:
        return context.leases.ttl_for(ttl_s)
    except TtlOutOfBounds as exc:
        raise ApiError(422, str(exc), field="ttl_s", limit=exc.limit) from None


@_lease_router.post("", response_model=LeaseOut, responses={**CONTROL_RESPONSES, **_REFUSED})
async def acquire_control(
    request: Request, call: LeaseCall, body: Annotated[ControlBody | None, Body()] = None
) -> LeaseOut:
    """Take the control lease (409 while another pilot holds it). With `takeover` the
    holder is asked first and has takeover_ask_s to grant it (409 when denied or
    unanswered); with `takeover` and `force` it is taken at once. Sending the current
    X-Lease-Id renews it instead."""
    body = body or ControlBody()
    vehicle, context, x_lease_id = call.vehicle, call.context, call.lease_id
    ttl_s = ttl_checked(context, body.ttl_s)
    context.leases.expire_due()  # a lapsed lease, or one whose process is gone, is free now
    held = context.leases.current(vehicle.sysid)
    if held is not None and x_lease_id is not None and same_secret(x_lease_id, held.lease_id):
        return lease_out(
            context.leases.renew(vehicle.sysid, x_lease_id, ttl_s=ttl_s), context, vehicle
        )
    holder = context.holder_name(body.client_name, "rest", request.client)
    try:
        if body.takeover:
            asking = context.leases.take_over(
                vehicle.sysid,
                holder,
                session="rest",
                ask_s=context.settings.takeover_ask_s,
                force=body.force,
                ttl_s=ttl_s,
            )
            lease = await unless_gone(asking, _request_gone(request))
        else:
            lease = context.leases.acquire(vehicle.sysid, holder, session="rest", ttl_s=ttl_s)
    except LeaseHeld as held_by:
        raise ApiError(409, str(held_by), holder=held_by.lease.holder) from None
    except TakeoverRefused as refused:
        raise ApiError(409, str(refused), holder=refused.holder) from None
    except AskerGone:
        # nobody reads this answer; 499 is what proxies log for a client that left
        raise ApiError(499, "the client asking for control went away") from None
    if body.client_pid is not None and request.client is not None:
        lease.process = verified_holder(body.client_pid, request.client.host, request.client.port)
    return lease_out(lease, context, vehicle)


@_lease_router.put("", response_model=LeaseOut, responses=CONTROL_RESPONSES)
async def renew_control(
    call: LeaseCall, body: Annotated[RenewBody | None, Body()] = None
) -> LeaseOut:
    """Renew the lease; optionally change its TTL and the client's label."""
    body = body or RenewBody()
    vehicle, context, x_lease_id = call.vehicle, call.context, call.lease_id
    ttl_s = ttl_checked(context, body.ttl_s) if body.ttl_s is not None else None
    lease = context.leases.renew(vehicle.sysid, x_lease_id, ttl_s=ttl_s)
    if body.client_name is not None:
        name = context.holder_name(body.client_name, lease.session, None)
        lease = context.leases.rename(vehicle.sysid, x_lease_id, name)
    return lease_out(lease, context, vehicle)


@_lease_router.get("", response_model=ControlStatusOut, responses=READ_RESPONSES)
async def control_status(vehicle: KnownVehicle, context: Context, _: Reader) -> ControlStatusOut:
    """Who holds control, since when, until when, and a pending takeover request."""
    lease = context.leases.current(vehicle.sysid)
    now = context.leases.now()
    last_end = _last_end(context, vehicle.sysid, now)
    if lease is None:
        return ControlStatusOut(last_end=last_end)
    asked = lease.request
    return ControlStatusOut(
        holder_pid=lease.process.pid if lease.process is not None else None,
        last_end=last_end,
        holder=lease.holder,
        session="ws" if lease.session == "ws" else "rest",
        since_s=round(max(0.0, now - lease.since), 3),
        expires_in_s=round(lease.expires_in_s(now), 3),
        ttl_s=lease.ttl_s,
        request=None
        if asked is None
        else TakeoverRequestOut(
            request_id=asked.request_id,
            by=asked.by,
            timeout_s=asked.timeout_s,
            expires_in_s=round(max(0.0, asked.asked_at + asked.timeout_s - now), 3),
        ),
    )


def _last_end(context: ApiContext, vehicle_id: int, now: float) -> LeaseEndOut | None:
    ended = context.leases.last_ended(vehicle_id)
    if ended is None or ended.end is None or ended.ended_at is None:
        return None
    return LeaseEndOut(
        holder=ended.holder,
        end=ended.end.value,
        ago_s=round(max(0.0, now - ended.ended_at), 3),
        holder_pid=ended.process.pid if ended.process is not None else None,
    )


@_lease_router.delete("", status_code=204, response_class=Response, responses=CONTROL_RESPONSES)
async def release_control(call: LeaseCall) -> Response:
    """Give control back. While the streamer runs, this applies on_operator_loss."""
    call.context.leases.release(call.vehicle.sysid, call.lease_id)
    return Response(status_code=204)


@_lease_router.post(
    "/requests/{request_id}",
    response_model=TakeoverAnswerOut,
    responses={**CONTROL_RESPONSES, 404: {"model": ErrorOut, "description": "no such request"}},
)
async def answer_takeover(
    request_id: str, body: TakeoverAnswerBody, call: LeaseCall
) -> TakeoverAnswerOut:
    """The holder grants or denies a takeover request (its X-Lease-Id proves it holds it)."""
    try:
        asked = call.context.leases.answer(
            call.vehicle.sysid, call.lease_id, request_id, body.grant
        )
    except UnknownRequest as exc:
        raise ApiError(404, str(exc)) from None
    return TakeoverAnswerOut(request_id=asked.request_id, grant=body.grant, by=asked.by)


@router.get("/control/audit", response_model=list[AuditEntryOut], responses=READ_RESPONSES)
async def control_audit(
    context: Context,
    _: Reader,
    vehicle: Annotated[int | None, Query(ge=0, le=255, description="one vehicle's only")] = None,
    limit: Annotated[int, Query(ge=1, le=AUDIT_LIMIT_MAX)] = 100,
) -> list[dict[str, Any]]:
    """The newest control and deadman events, oldest first; kept across restarts in
    `<log_dir>/control-audit.jsonl`."""
    return context.audit.entries(vehicle, limit)


router.include_router(_lease_router)
