"""The control lease's calls as REST and the fleet edge make them: acquire (or take over,
asking the holder first or forcing it), renew, inspect, release, answer a takeover request.

Plain arguments in, wire models out; a refusal is raised as the lease's own error
(``LeaseHeld``, ``TakeoverRefused``, ``TtlOutOfBounds``, ``UnknownRequest``, ``LeaseInvalid``,
``AskerGone``), which ``server.http.errors`` turns into the answer both give."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable

from server.control.auth import same_secret
from server.control.holder_process import verified_holder
from server.control.lease import Lease, LeaseManager
from server.link import Vehicle
from skyhelm_wire.control import (
    ControlBody,
    ControlStatusOut,
    LeaseEndOut,
    LeaseOut,
    RenewBody,
    TakeoverAnswerBody,
    TakeoverAnswerOut,
    TakeoverRequestOut,
)
from skyhelm_wire.setpoints import setpoint_body

# where a call comes from: (host, port), as an ASGI scope's client
Client = tuple[str, int]


class AskerGone(Exception):
    """The client asking for control went away before the holder answered."""


def holder_name(pilot: str, client_name: str | None, session: str, client: Client | None) -> str:
    """A session's name: the token's name, then the client's label, or where it connects
    from when it gave none ("pilot · Chrome tab 7f3a", "pilot · rest 10.0.0.2:5121")."""
    label = (client_name or "").strip()[:64]
    if not label:
        label = f"{session} {client[0]}:{client[1]}" if client else session
    return f"{pilot} · {label}"


def lease_out(leases: LeaseManager, lease: Lease, vehicle: Vehicle | None) -> LeaseOut:
    """The lease as its holder sees it, with the setpoint being flown so it starts from it."""
    now = leases.now()
    flying = vehicle.setpoint if vehicle is not None and vehicle.streamer_active else None
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


async def acquire(
    leases: LeaseManager,
    vehicle: Vehicle,
    body: ControlBody,
    lease_id: str | None,
    *,
    pilot: str,
    client: Client | None,
    ask_s: float,
    gone: Callable[[], Awaitable[None]],
) -> LeaseOut:
    """Take the lease (LeaseHeld while another holds it); with ``takeover`` ask the holder
    (``ask_s`` to answer) or, with ``force``, take it at once. The current lease id renews
    instead. ``gone()`` completes when the asking client leaves."""
    ttl_s = leases.ttl_for(body.ttl_s)
    leases.expire_due()  # a lapsed lease, or one whose process is gone, is free now
    held = leases.current(vehicle.sysid)
    if held is not None and lease_id is not None and same_secret(lease_id, held.lease_id):
        return lease_out(leases, leases.renew(vehicle.sysid, lease_id, ttl_s=ttl_s), vehicle)
    holder = holder_name(pilot, body.client_name, "rest", client)
    if body.takeover:
        asking = leases.take_over(
            vehicle.sysid, holder, session="rest", ask_s=ask_s, force=body.force, ttl_s=ttl_s
        )
        lease = await unless_gone(asking, gone())
    else:
        lease = leases.acquire(vehicle.sysid, holder, session="rest", ttl_s=ttl_s)
    if body.client_pid is not None and client is not None:
        lease.process = verified_holder(body.client_pid, client[0], client[1])
    return lease_out(leases, lease, vehicle)


def renew(
    leases: LeaseManager, vehicle: Vehicle, body: RenewBody, lease_id: str | None, *, pilot: str
) -> LeaseOut:
    """Renew the lease; optionally change its TTL and the client's label."""
    ttl_s = leases.ttl_for(body.ttl_s) if body.ttl_s is not None else None
    lease = leases.renew(vehicle.sysid, lease_id, ttl_s=ttl_s)
    if body.client_name is not None:
        lease = leases.rename(
            vehicle.sysid, lease_id, holder_name(pilot, body.client_name, lease.session, None)
        )
    return lease_out(leases, lease, vehicle)


def status(leases: LeaseManager, vehicle_id: int) -> ControlStatusOut:
    """Who holds control, since when, until when, and a pending takeover request."""
    lease = leases.current(vehicle_id)
    now = leases.now()
    last_end = _last_end(leases, vehicle_id, now)
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


def _last_end(leases: LeaseManager, vehicle_id: int, now: float) -> LeaseEndOut | None:
    ended = leases.last_ended(vehicle_id)
    if ended is None or ended.end is None or ended.ended_at is None:
        return None
    return LeaseEndOut(
        holder=ended.holder,
        end=ended.end.value,
        ago_s=round(max(0.0, now - ended.ended_at), 3),
        holder_pid=ended.process.pid if ended.process is not None else None,
    )


def release(leases: LeaseManager, vehicle: Vehicle, lease_id: str | None) -> None:
    """Give control back. While the streamer runs, this applies on_operator_loss."""
    leases.release(vehicle.sysid, lease_id)


def answer_takeover(
    leases: LeaseManager,
    vehicle: Vehicle,
    lease_id: str | None,
    request_id: str,
    body: TakeoverAnswerBody,
) -> TakeoverAnswerOut:
    """The holder grants or denies a takeover request (its lease id proves it holds it)."""
    asked = leases.answer(vehicle.sysid, lease_id, request_id, body.grant)
    return TakeoverAnswerOut(request_id=asked.request_id, grant=body.grant, by=asked.by)
