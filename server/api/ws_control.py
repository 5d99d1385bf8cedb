"""The control socket: the pilot session, which holds the control lease while open and
heartbeating, and carries setpoints and commands, each answered with a result."""

from __future__ import annotations

import asyncio
import json
import logging
from typing import Any

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from pydantic import TypeAdapter

from server.api.auth import Role
from server.api.deps import ApiContext
from server.api.errors import COMMAND_STATUS, ApiError, command_out, error_status
from server.api.lease import Lease, LeaseEnd, LeaseHeld
from server.api.operations import OPERATIONS
from server.api.routes.setpoint import sent_out
from server.api.schemas import SetpointBody
from server.api.ws_common import (
    CLOSE_LEASE_HELD,
    CLOSE_LEASE_LOST,
    CLOSE_NOT_FOUND,
    Sender,
    admit,
    close_socket,
)
from server.link import Vehicle

log = logging.getLogger(__name__)

router = APIRouter()
_setpoint_adapter: TypeAdapter[Any] = TypeAdapter(SetpointBody)


@router.websocket("/ws/control")
async def control(
    websocket: WebSocket, vehicle: int, takeover: bool = False, client_name: str | None = None
) -> None:
    """The pilot session: holds the control lease while open and heartbeating."""
    context = await admit(websocket, Role.PILOT)
    if context is None:
        return
    target = context.registry.get(vehicle)
    if target is None:
        await close_socket(websocket, CLOSE_NOT_FOUND, f"no vehicle {vehicle}")
        return
    client = websocket.client
    holder = (client_name or "")[:64] or (
        f"pilot@{client.host}:{client.port}" if client else "pilot"
    )
    try:
        lease = context.leases.acquire(target.sysid, holder, session="ws", takeover=takeover)
    except LeaseHeld as held:
        await websocket.send_json(
            {"type": "error", "reason": str(held), "holder": held.lease.holder}
        )
        await close_socket(websocket, CLOSE_LEASE_HELD, "control held by another pilot")
        return
    sender = Sender(websocket)
    session = _ControlSession(context, target, lease, sender)
    try:
        await sender.send_json(
            {"type": "lease", "lease_id": lease.lease_id, "ttl_s": lease.ttl_s, "holder": holder}
        )
        await session.run(websocket)
    except WebSocketDisconnect:
        pass
    finally:
        await session.finish()
        if context.leases.current(target.sysid) is lease:
            context.leases.release(target.sysid, lease.lease_id, LeaseEnd.CLOSED)
        await close_socket(websocket, 1000)


class _ControlSession:
    def __init__(self, context: ApiContext, vehicle: Vehicle, lease: Lease, sender: Sender) -> None:
        self._context = context
        self._vehicle = vehicle
        self._lease = lease
        self._sender = sender
        self._commands: set[asyncio.Task[None]] = set()

    async def run(self, websocket: WebSocket) -> None:
        receiver = asyncio.ensure_future(self._receive(websocket))
        lost = asyncio.ensure_future(self._lease.ended.wait())
        try:
            await asyncio.wait({receiver, lost}, return_when=asyncio.FIRST_COMPLETED)
            if lost.done() and not receiver.done():
                end = self._lease.end.value if self._lease.end else "ended"
                await self._sender.send_json({"type": "lease", "state": end})
                await close_socket(websocket, CLOSE_LEASE_LOST, f"control lease {end}")
        finally:
            for task in (receiver, lost):
                task.cancel()
            await asyncio.gather(receiver, lost, return_exceptions=True)

    async def finish(self) -> None:
        for task in self._commands:
            task.cancel()
        await asyncio.gather(*self._commands, return_exceptions=True)

    async def _receive(self, websocket: WebSocket) -> None:
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return
            # Binary frames are read as UTF-8 JSON too rather than ending the session.
            text = message.get("text") or (message.get("bytes") or b"").decode(errors="replace")
            await self._handle(text)

    async def _handle(self, text: str) -> None:
        request_id: Any = None
        try:
            message = json.loads(text)
            if not isinstance(message, dict):
                raise ApiError(422, "a message is a JSON object with a type", field="type")
            request_id = message.get("id")
            self._context.leases.renew(self._vehicle.sysid, self._lease.lease_id)
            kind = message.get("type")
            if kind == "heartbeat":
                await self._reply(request_id, "heartbeat", 200, {"ttl_s": self._lease.ttl_s})
            elif kind == "setpoint":
                await self._setpoint(request_id, message.get("setpoint"))
            elif kind == "command":
                self._start_command(request_id, message.get("name"), message.get("args"))
            else:
                raise ApiError(422, "type must be heartbeat, setpoint or command", field="type")
        except (json.JSONDecodeError, UnicodeDecodeError):
            await self._reply(request_id, "error", 422, {"detail": {"reason": "not JSON"}})
        except Exception as exc:
            await self._reply_error(request_id, "error", exc)

    async def _setpoint(self, request_id: Any, body: Any) -> None:
        try:
            setpoint = _setpoint_adapter.validate_python(body)
            sent = await self._vehicle.set_setpoint(setpoint.to_link())
        except Exception as exc:
            await self._reply_error(request_id, "setpoint", exc)
            return
        await self._reply(request_id, "setpoint", 200, sent_out(sent).model_dump(mode="json"))

    def _start_command(self, request_id: Any, name: Any, args: Any) -> None:
        task = asyncio.create_task(self._command(request_id, name, args))
        self._commands.add(task)
        task.add_done_callback(self._commands.discard)

    async def _command(self, request_id: Any, name: Any, args: Any) -> None:
        try:
            operation = OPERATIONS.get(name) if isinstance(name, str) else None
            if operation is None:
                raise ApiError(
                    422, f"unknown command; one of {', '.join(OPERATIONS)}", field="name"
                )
            body = operation.body.model_validate(args if args is not None else {})
            with self._context.leases.hold(self._vehicle.sysid, self._lease.lease_id):
                if not self._vehicle.connected:
                    raise ApiError(503, f"vehicle {self._vehicle.sysid} is not connected")
                result = await operation.run(self._vehicle, body)
        except Exception as exc:
            await self._reply_error(request_id, "command", exc)
            return
        out = command_out(result).model_dump(mode="json")
        await self._reply(request_id, "command", COMMAND_STATUS[result.outcome], out)

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
