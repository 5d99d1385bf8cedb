"""WebSockets: telemetry for anyone with a token, the control session for one pilot.

Slow-client policy (the one place it is decided):
- state snapshots are latest-wins: a client gets at most `rate_hz` of them, each the newest
  when it is sent, so a client that reads slowly simply receives fewer, never a backlog;
- statustext and events wait in the vehicle's per-client queue of EVENT_BACKLOG entries,
  which drops its oldest entry when full;
- a single send that does not complete within SEND_TIMEOUT_S closes the client (code 1008):
  a client that stops reading cannot hold server memory or the event loop.

Close codes: 4401 no/wrong token, 4403 observer token on the control socket, a read-only
replay, or a foreign Origin, 4404 unknown vehicle, 4409 control held by another pilot,
4408 lease lost.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Awaitable
from typing import Any
from urllib.parse import urlsplit

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from pydantic import TypeAdapter
from starlette.websockets import WebSocketState

from server.api.auth import Role, token_from
from server.api.deps import READ_ONLY_REASON, ApiContext
from server.api.errors import COMMAND_STATUS, ApiError, command_out, error_status
from server.api.lease import Lease, LeaseEnd, LeaseHeld
from server.api.operations import OPERATIONS
from server.api.routes.setpoint import sent_out
from server.api.schemas import SetpointBody
from server.api.views import finite, state_dict
from server.link import Vehicle, VehicleEvent

log = logging.getLogger(__name__)

EVENT_BACKLOG = 256
SEND_TIMEOUT_S = 5.0
MIN_RATE_HZ = 0.1
CLOSE_UNAUTHORIZED = 4401
CLOSE_FORBIDDEN = 4403
CLOSE_NOT_FOUND = 4404
CLOSE_LEASE_LOST = 4408
CLOSE_LEASE_HELD = 4409

router = APIRouter()
_setpoint_adapter: TypeAdapter[Any] = TypeAdapter(SetpointBody)


class _Sender:
    """Serialises sends on one socket, with the send timeout of the policy above."""

    def __init__(self, websocket: WebSocket) -> None:
        self._websocket = websocket
        self._lock = asyncio.Lock()

    async def send_text(self, text: str) -> None:
        async with self._lock:
            try:
                # asyncio.timeout, unlike wait_for, adds no task per message
                async with asyncio.timeout(SEND_TIMEOUT_S):
                    await self._websocket.send_text(text)
            except TimeoutError:
                await _close(self._websocket, 1008, "client too slow")
                raise WebSocketDisconnect(1008) from None

    async def send_json(self, message: dict[str, Any]) -> None:
        await self.send_text(json.dumps(message, allow_nan=False))


class StateText:
    """Serialised snapshots shared by every telemetry client of a vehicle: the first client
    to send after a change builds and encodes the snapshot; every other client sends that
    same text until the vehicle's state_version moves on."""

    def __init__(self, context: ApiContext) -> None:
        self._context = context
        self._texts: dict[int, tuple[Vehicle, int, str]] = {}

    def text(self, vehicle: Vehicle) -> str:
        version = vehicle.state_version
        cached = self._texts.get(vehicle.sysid)
        if cached is not None and cached[0] is vehicle and cached[1] == version:
            return cached[2]
        text = self._encode(vehicle)
        self._texts[vehicle.sysid] = (vehicle, version, text)
        return text

    async def close(self) -> None:
        self._texts.clear()

    def _encode(self, vehicle: Vehicle) -> str:
        state = vehicle.snapshot()
        fields = state_dict(state, self._context.leases)
        # `type` names the message here, so the vehicle's type travels as vehicle_type.
        fields["vehicle_type"] = fields.pop("type")
        message = {"type": "state", "vehicle": state.sysid, **fields}
        return json.dumps(message, separators=(",", ":"))


def _context(websocket: WebSocket) -> ApiContext:
    context: ApiContext = websocket.app.state.api
    return context


def _origin_allowed(websocket: WebSocket, allowed: list[str]) -> bool:
    """Browsers always send Origin; scripts usually do not. Same host, or a configured one."""
    origin = websocket.headers.get("origin")
    if origin is None or origin in allowed:
        return True
    return urlsplit(origin).netloc == websocket.headers.get("host")


async def _close(websocket: WebSocket, code: int, reason: str = "") -> None:
    if websocket.application_state == WebSocketState.CONNECTED:
        with contextlib.suppress(RuntimeError, WebSocketDisconnect):
            await websocket.close(code, reason)


async def _admit(websocket: WebSocket, need: Role) -> ApiContext | None:
    """Accept the socket, then close it with the right code if it may not stay."""
    context = _context(websocket)
    await websocket.accept()
    role = context.tokens.role_of(
        token_from(websocket.headers, websocket.query_params, websocket.cookies)
    )
    if role is None:
        await _close(websocket, CLOSE_UNAUTHORIZED, "missing or wrong token")
        return None
    if not _origin_allowed(websocket, context.settings.cors_origins):
        await _close(websocket, CLOSE_FORBIDDEN, "origin not allowed")
        return None
    if need is Role.PILOT and context.read_only:
        await _close(websocket, CLOSE_FORBIDDEN, READ_ONLY_REASON)
        return None
    if need is Role.PILOT and role is not Role.PILOT:
        await _close(websocket, CLOSE_FORBIDDEN, "the control socket needs the pilot token")
        return None
    return context


async def _run_until_disconnect(websocket: WebSocket, *jobs: Awaitable[None]) -> None:
    """Run the jobs until the client goes away or one of them ends; then cancel the rest."""
    tasks = [asyncio.ensure_future(job) for job in (_drain_until_disconnect(websocket), *jobs)]
    try:
        done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        for task in done:
            exc = None if task.cancelled() else task.exception()
            if exc is not None and not isinstance(exc, WebSocketDisconnect):
                raise exc
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


async def _drain_until_disconnect(websocket: WebSocket) -> None:
    while True:
        message = await websocket.receive()
        if message["type"] == "websocket.disconnect":
            return


# ---- telemetry ---------------------------------------------------------------------------


@router.websocket("/ws/telemetry")
async def telemetry(
    websocket: WebSocket, vehicle: int | None = None, rate_hz: float = 10.0
) -> None:
    """`{type: "state"}` snapshots of one vehicle (or all) at rate_hz (capped), plus
    `{type: "statustext"}` and `{type: "event"}` as they happen."""
    context = await _admit(websocket, Role.OBSERVER)
    if context is None:
        return
    if vehicle is None:
        vehicles = context.registry.all()
    else:
        found = context.registry.get(vehicle)
        if found is None:
            await _close(websocket, CLOSE_NOT_FOUND, f"no vehicle {vehicle}")
            return
        vehicles = [found]
    if not rate_hz > 0:  # also refuses NaN
        rate_hz = MIN_RATE_HZ
    period_s = 1.0 / min(max(rate_hz, MIN_RATE_HZ), context.settings.telemetry_max_rate_hz)
    sender = _Sender(websocket)
    state_text: StateText = websocket.app.state.state_text
    jobs: list[Awaitable[None]] = []
    for each in vehicles:
        jobs.append(_pump_states(each, sender, state_text, period_s))
        jobs.append(_pump_events(each, sender))
    await _run_until_disconnect(websocket, *jobs)


async def _pump_states(
    vehicle: Vehicle, sender: _Sender, state_text: StateText, period_s: float
) -> None:
    # The subscription does the rate limit: each client gets the first change after its
    # period is up, so what it receives is fresh; clients keep the phases they connected
    # with, so a vehicle update wakes only the few whose period is up, not all at once.
    subscription = vehicle.subscribe(min_interval_s=period_s)
    try:
        while await subscription.changed():
            await sender.send_text(state_text.text(vehicle))
    finally:
        subscription.close()


async def _pump_events(vehicle: Vehicle, sender: _Sender) -> None:
    queue = vehicle.subscribe_events(EVENT_BACKLOG)
    try:
        while True:
            await sender.send_json(event_message(vehicle.sysid, await queue.get()))
    finally:
        unsubscribe = getattr(vehicle, "unsubscribe_events", None)
        if unsubscribe is not None:
            unsubscribe(queue)


def event_message(vehicle_id: int, event: VehicleEvent) -> dict[str, Any]:
    if event.kind == "statustext":
        return {
            "type": "statustext",
            "vehicle": vehicle_id,
            "time_s": event.time_s,
            **finite(dict(event.data)),
        }
    return {
        "type": "event",
        "vehicle": vehicle_id,
        "kind": event.kind,
        "time_s": event.time_s,
        "data": finite(_jsonable(event.data)),
    }


def _jsonable(value: Any) -> Any:
    return json.loads(json.dumps(value, default=str))


# ---- control -----------------------------------------------------------------------------


@router.websocket("/ws/control")
async def control(
    websocket: WebSocket, vehicle: int, takeover: bool = False, client_name: str | None = None
) -> None:
    """The pilot session: holds the control lease while open and heartbeating."""
    context = await _admit(websocket, Role.PILOT)
    if context is None:
        return
    target = context.registry.get(vehicle)
    if target is None:
        await _close(websocket, CLOSE_NOT_FOUND, f"no vehicle {vehicle}")
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
        await _close(websocket, CLOSE_LEASE_HELD, "control held by another pilot")
        return
    sender = _Sender(websocket)
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
        await _close(websocket, 1000)


class _ControlSession:
    def __init__(
        self, context: ApiContext, vehicle: Vehicle, lease: Lease, sender: _Sender
    ) -> None:
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
                await _close(websocket, CLOSE_LEASE_LOST, f"control lease {end}")
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
