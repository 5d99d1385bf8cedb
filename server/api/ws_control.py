"""The control socket: the pilot session, which holds the control lease while open and
not silent for its TTL, and carries setpoints (live ones watched by the deadman), commands,
and the holder's answers to takeover requests, each answered with a result."""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from pydantic import TypeAdapter

from server.control.auth import Role
from server.control.lease import (
    Lease,
    LeaseEnd,
    LeaseHeld,
    TakeoverRefused,
    TtlOutOfBounds,
    UnknownRequest,
)
from server.control.lease_ops import AskerGone, lease_out, unless_gone
from server.control.operations import OPERATIONS, run_command, run_intent, sent_out
from server.control.vehicle_ops import fly_sticks, stop_sticks
from server.http.context import ApiContext, require_connected
from server.http.errors import (
    ApiError,
    command_answer,
    command_status,
    error_status,
    non_finite_field,
    refuse_non_finite,
)
from server.http.ws_common import (
    CLOSE_BAD_REQUEST,
    CLOSE_LEASE_HELD,
    CLOSE_LEASE_LOST,
    CLOSE_NOT_FOUND,
    Sender,
    admit,
    close_socket,
)
from server.link import Vehicle
from skyhelm_wire.calls import API_PREFIX, CALL, COMMAND_CALLS, CallSpec
from skyhelm_wire.intents import IntentOut
from skyhelm_wire.sockets import SOCKET

log = logging.getLogger(__name__)

router = APIRouter(prefix=API_PREFIX)
# what the socket takes, as the wire's calls: the commands and intents made under the lease
# (which the socket holds) by name, the setpoint's and the sticks' bodies
SOCKET_CALLS: dict[str, CallSpec] = {
    call.name: call for call in COMMAND_CALLS if call.access == "control"
}
_UNKNOWN_COMMAND = "unknown command; one of " + ", ".join(
    [*(c.name for c in COMMAND_CALLS if c.answer is not IntentOut),
     *sorted(c.name for c in COMMAND_CALLS if c.answer is IntentOut)]
)  # fmt: skip


def _body_adapter(name: str) -> TypeAdapter[Any]:
    body: Any = CALL[name].body
    return TypeAdapter(body)


_setpoint_adapter = _body_adapter("set_setpoint")
_sticks_adapter = _body_adapter("fly_sticks")


@router.websocket(SOCKET["control"].route)
async def control(
    websocket: WebSocket,
    vehicle: int,
    takeover: bool = False,
    force: bool = False,
    client_name: str | None = None,
    ttl_s: float | None = None,
) -> None:
    """The pilot session: holds the control lease while open and not silent for ttl_s.
    With takeover the holder is asked first (unless force); the first message is the lease."""
    context = await admit(websocket, SOCKET["control"])
    if context is None:
        return
    target = context.registry.get(vehicle)
    if target is None:
        await close_socket(websocket, CLOSE_NOT_FOUND, f"no vehicle {vehicle}")
        return
    lease = await _acquire(websocket, context, target, takeover, force, client_name, ttl_s)
    if lease is None:
        return
    sender = Sender(websocket)
    session = _ControlSession(context, target, lease, sender)
    try:
        await sender.send_json(
            {"type": "lease", **lease_out(context.leases, lease, target).model_dump(mode="json")}
        )
        await session.run(websocket)
    except WebSocketDisconnect:
        pass
    finally:
        await session.finish()
        if context.leases.current(target.sysid) is lease:
            context.leases.release(target.sysid, lease.lease_id, LeaseEnd.CLOSED)
        await close_socket(websocket, 1000)


async def _acquire(
    websocket: WebSocket,
    context: ApiContext,
    vehicle: Vehicle,
    takeover: bool,
    force: bool,
    client_name: str | None,
    ttl_s: float | None,
) -> Lease | None:
    """The session's lease, or None after telling the client why not and closing."""
    holder = context.holder_name(client_name, "ws", websocket.client)
    try:
        if takeover:
            asking = context.leases.take_over(
                vehicle.sysid,
                holder,
                session="ws",
                ask_s=context.settings.takeover_ask_s,
                force=force,
                ttl_s=ttl_s,
            )
            # what the client sends before its lease is not read as requests
            return await unless_gone(asking, _disconnected(websocket))
        return context.leases.acquire(vehicle.sysid, holder, session="ws", ttl_s=ttl_s)
    except AskerGone:
        return None
    except TtlOutOfBounds as exc:
        await websocket.send_json(
            {"type": "error", "reason": str(exc), "field": "ttl_s", "limit": exc.limit}
        )
        await close_socket(websocket, CLOSE_BAD_REQUEST, "ttl_s out of bounds")
    except (LeaseHeld, TakeoverRefused) as refused:
        holder_now = refused.lease.holder if isinstance(refused, LeaseHeld) else refused.holder
        await websocket.send_json({"type": "error", "reason": str(refused), "holder": holder_now})
        await close_socket(websocket, CLOSE_LEASE_HELD, "control held by another pilot")
    return None


async def _disconnected(websocket: WebSocket) -> None:
    while (await websocket.receive())["type"] != "websocket.disconnect":
        pass


def _id_and_type(text: str) -> tuple[Any, str]:
    """A refused message's id and type, when it has them, to answer it by."""
    try:
        message = json.loads(text)
    except ValueError:
        return None, "error"
    if not isinstance(message, dict):
        return None, "error"
    request_id, kind = message.get("id"), message.get("type")
    if non_finite_field(request_id) is not None:
        request_id = None
    return request_id, kind if isinstance(kind, str) and len(kind) <= 32 else "error"


class _ControlSession:
    def __init__(self, context: ApiContext, vehicle: Vehicle, lease: Lease, sender: Sender) -> None:
        self._context = context
        self._vehicle = vehicle
        self._lease = lease
        self._sender = sender
        self._commands: set[asyncio.Future[None]] = set()
        self._refused_in_a_row = 0
        context.leases.add_listener(self._on_lease)

    async def run(self, websocket: WebSocket) -> None:
        receiver = asyncio.ensure_future(self._receive(websocket))
        lost = asyncio.ensure_future(self._lease.ended.wait())
        try:
            await asyncio.wait({receiver, lost}, return_when=asyncio.FIRST_COMPLETED)
            if lost.done() and not receiver.done():
                end = self._lease.end.value if self._lease.end else "ended"
                told: dict[str, Any] = {"type": "lease", "state": end}
                if self._lease.end is LeaseEnd.TAKEN_OVER:
                    told["by"] = self._lease.taken_by
                await self._sender.send_json(told)
                await close_socket(websocket, CLOSE_LEASE_LOST, f"control lease {end}")
        finally:
            for task in (receiver, lost):
                task.cancel()
            await asyncio.gather(receiver, lost, return_exceptions=True)

    async def finish(self) -> None:
        self._context.leases.remove_listener(self._on_lease)
        for task in self._commands:
            task.cancel()
        await asyncio.gather(*self._commands, return_exceptions=True)

    def _on_lease(self, lease: Lease, what: str) -> None:
        """The holder hears of a takeover request on its own socket, to grant or deny it."""
        request = lease.request
        if lease is not self._lease or what != "takeover_requested" or request is None:
            return
        message = {
            "type": "takeover_requested",
            "request_id": request.request_id,
            "by": request.by,
            "timeout_s": request.timeout_s,
        }
        self._track(asyncio.ensure_future(self._sender.send_json(message)))

    def _track(self, task: asyncio.Future[None]) -> None:
        self._commands.add(task)
        task.add_done_callback(self._finished)

    def _finished(self, task: asyncio.Future[None]) -> None:
        """An answer that could not be sent because the client went away ends quietly; any
        other failure is logged once, here (nobody else awaits these tasks)."""
        self._commands.discard(task)
        if task.cancelled():
            return
        exc = task.exception()
        if exc is not None and not isinstance(exc, WebSocketDisconnect):
            log.error("control message failed on vehicle %s", self._vehicle.sysid, exc_info=exc)

    async def _receive(self, websocket: WebSocket) -> None:
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return
            # Binary frames are read as UTF-8 JSON too rather than ending the session.
            text = message.get("text") or (message.get("bytes") or b"").decode(errors="replace")
            if not await self._within_rate(websocket, text):
                if self._refused_in_a_row >= self._context.guards.ws_close_after:
                    return
                continue
            await self._handle(text)

    async def _within_rate(self, websocket: WebSocket, text: str) -> bool:
        """The token's message bucket (security.py): a refused message is answered 429 with
        retry_after_s; refused ws_abuse_close_after times in a row, the socket is closed
        (1008) and the lease released."""
        guards = self._context.guards
        wait_s = guards.ws_messages.take(Role.PILOT.value)
        if wait_s <= 0:
            self._refused_in_a_row = 0
            return True
        self._refused_in_a_row += 1
        limit = guards.ws_messages
        reason = f"rate limit: {limit.rate_per_s:g} messages/s (burst {limit.burst:g}) per token"
        retry_after_s = round(wait_s, 3)
        if self._refused_in_a_row >= guards.ws_close_after:
            await self._sender.send_json(
                {
                    "type": "error",
                    "reason": f"{reason}; {self._refused_in_a_row} refused in a row: closing",
                    "retry_after_s": retry_after_s,
                }
            )
            await close_socket(websocket, 1008, "rate limit exceeded")
            return False
        request_id, kind = _id_and_type(text)
        detail = {"reason": reason, "retry_after_s": retry_after_s}
        await self._reply(request_id, kind, 429, {"detail": detail})
        return False

    async def _handle(self, text: str) -> None:
        request_id: Any = None
        try:
            message = json.loads(text)
            if not isinstance(message, dict):
                raise ApiError(422, "a message is a JSON object with a type", field="type")
            # json.loads takes NaN and Infinity: an id holding one could not be answered
            request_id = message.get("id")
            if non_finite_field(request_id) is not None:
                request_id = None
            self._context.leases.renew(self._vehicle.sysid, self._lease.lease_id)
            refuse_non_finite(message)
            kind = message.get("type")
            if kind == "heartbeat":
                await self._reply(request_id, "heartbeat", 200, {"ttl_s": self._lease.ttl_s})
            elif kind == "setpoint":
                live = message.get("live", False)
                if not isinstance(live, bool):
                    raise ApiError(422, "live must be true or false", field="live")
                await self._setpoint(request_id, message.get("setpoint"), live=live)
            elif kind == "sticks":
                await self._sticks(request_id, message)
            elif kind == "command":
                self._start_command(request_id, message.get("name"), message.get("args"))
            elif kind == "takeover_answer":
                await self._takeover_answer(request_id, message)
            else:
                raise ApiError(
                    422,
                    "type must be heartbeat, setpoint, sticks, command or takeover_answer",
                    field="type",
                )
        except (json.JSONDecodeError, UnicodeDecodeError):
            await self._reply(request_id, "error", 422, {"detail": {"reason": "not JSON"}})
        except Exception as exc:
            await self._reply_error(request_id, "error", exc)

    async def _setpoint(self, request_id: Any, body: Any, *, live: bool) -> None:
        try:
            setpoint = _setpoint_adapter.validate_python(body)
            sent = await self._vehicle.set_setpoint(setpoint.to_link())
        except Exception as exc:
            await self._reply_error(request_id, "setpoint", exc)
            return
        self._context.deadman.watch_live(self._vehicle.sysid, live=live)
        await self._reply(request_id, "setpoint", 200, sent_out(sent).model_dump(mode="json"))

    async def _sticks(self, request_id: Any, message: dict[str, Any]) -> None:
        """Sticks (MANUAL_CONTROL at 25 Hz, live), or ``"stop": true`` to stop sending.
        Answered only when the message has an id: the page sends 25 a second."""
        try:
            with self._held():
                if message.get("stop") is True:
                    out = stop_sticks(self._context.deadman, self._vehicle)
                else:
                    body = _sticks_adapter.validate_python(message.get("sticks") or {})
                    out = fly_sticks(self._context.deadman, self._vehicle, body)
        except Exception as exc:
            await self._reply_error(request_id, "sticks", exc)
            return
        if request_id is not None:
            await self._reply(request_id, "sticks", 200, out.model_dump(mode="json"))

    async def _takeover_answer(self, request_id: Any, message: dict[str, Any]) -> None:
        asked_id, grant = message.get("request_id"), message.get("grant")
        if not isinstance(asked_id, str):
            raise ApiError(422, "request_id must be the request's id", field="request_id")
        if not isinstance(grant, bool):
            raise ApiError(422, "grant must be true or false", field="grant")
        try:
            asked = self._context.leases.answer(
                self._vehicle.sysid, self._lease.lease_id, asked_id, grant
            )
        except UnknownRequest as exc:
            raise ApiError(404, str(exc), field="request_id") from None
        body = {"request_id": asked.request_id, "grant": grant, "by": asked.by}
        await self._reply(request_id, "takeover_answer", 200, body)

    def _start_command(self, request_id: Any, name: Any, args: Any) -> None:
        self._track(asyncio.create_task(self._command(request_id, name, args)))

    async def _command(self, request_id: Any, name: Any, args: Any) -> None:
        """A command or an intent of the wire's table by its name, run by the same
        operations as its REST route."""
        try:
            call = SOCKET_CALLS.get(name) if isinstance(name, str) else None
            if call is None:
                raise ApiError(422, _UNKNOWN_COMMAND, field="name")
            if call.answer is IntentOut:
                status, out = await self._intent(call.name, args)
            else:
                status, out = await self._operation(call.name, args)
        except Exception as exc:
            await self._reply_error(request_id, "command", exc)
            return
        await self._reply(request_id, "command", status, out)

    async def _operation(self, name: str, args: Any) -> tuple[int, dict[str, Any]]:
        body = OPERATIONS[name].body.model_validate(args if args is not None else {})
        with self._held():
            result = await run_command(name, self._vehicle, body)
        return command_answer(result)

    async def _intent(self, name: str, args: Any) -> tuple[int, dict[str, Any]]:
        with self._held():
            answer = await run_intent(name, self._vehicle, args)
        self._context.deadman.watch_live(self._vehicle.sysid, live=answer.live)
        return command_status(answer.outcome), answer.body

    @contextmanager
    def _held(self) -> Iterator[None]:
        """The lease held (and renewed) for one call, on a connected vehicle."""
        with self._context.leases.hold(self._vehicle.sysid, self._lease.lease_id):
            require_connected(self._vehicle)
            yield

    async def _reply(
        self, request_id: Any, request: str, status: int, body: dict[str, Any]
    ) -> None:
        await self._sender.send_json(
            {
                "type": "result",
                "id": request_id,
                "request": request,
                "status": status,
                "ok": status < 300,
                "body": body,
            }
        )

    async def _reply_error(self, request_id: Any, request: str, exc: Exception) -> None:
        answer = error_status(exc)
        if answer is None:
            log.exception("control message failed on vehicle %s", self._vehicle.sysid)
            answer = 500, {"reason": f"internal error: {type(exc).__name__}"}
        status, detail = answer
        await self._reply(request_id, request, status, {"detail": detail})
