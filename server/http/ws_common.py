"""What both WebSockets share: admission (token, Origin, role), serialised sends with a
timeout, close codes, and running a socket's jobs until the client goes away.

Slow-client policy for sends (state itself is latest-wins, see slots.py): statustext and
events wait in the vehicle's per-client queue of EVENT_BACKLOG entries, which drops its
oldest entry when full; a single send that does not complete within SEND_TIMEOUT_S closes
the client (code 1008): a client that stops reading cannot hold server memory or the event
loop.

Close codes: 4401 no/wrong token, 4403 observer token on the control socket or a read-only
replay, 4404 unknown vehicle, 4409 control held by another pilot (or a takeover denied or
unanswered), 4408 lease lost (expired, taken over), 4422 a bad query parameter (ttl_s
outside the server's bounds), 1008 sustained abuse of the control socket's rate limit. A
foreign Origin and a locked-out address are refused at the handshake (HTTP 403 / 429,
security.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import Awaitable
from typing import Any

from fastapi import WebSocket, WebSocketDisconnect
from starlette.websockets import WebSocketState

from server.control.auth import Role, token_from
from server.control.slots import EVENT_BACKLOG as EVENT_BACKLOG
from server.http.context import READ_ONLY_REASON, ApiContext
from server.http.security import origin_allowed
from skyhelm_wire.sockets import SocketSpec

SEND_TIMEOUT_S = 5.0
CLOSE_UNAUTHORIZED = 4401
CLOSE_FORBIDDEN = 4403
CLOSE_NOT_FOUND = 4404
CLOSE_LEASE_LOST = 4408
CLOSE_LEASE_HELD = 4409
CLOSE_BAD_REQUEST = 4422


class Sender:
    """Serialises sends on one socket, with the send timeout of the policy above.

    The timeout is a watchdog per socket, not a timer per message: a timer armed and
    cancelled around every send (asyncio.timeout) costs more than the send itself when a
    tick goes to a hundred sockets. The watchdog is armed when a send starts and none is
    armed, and when it fires it either cancels a send pending for SEND_TIMEOUT_S (closing
    the client with 1008) or re-arms for the pending one, or goes idle."""

    def __init__(self, websocket: WebSocket) -> None:
        self._websocket = websocket
        self._lock = asyncio.Lock()
        self._sending: asyncio.Task[Any] | None = None
        self._started_s = 0.0
        self._watchdog: asyncio.TimerHandle | None = None
        self._timed_out = False

    async def send_text(self, text: str) -> None:
        async with self._lock:
            loop = asyncio.get_running_loop()
            self._sending = asyncio.current_task()
            self._started_s = loop.time()
            if self._watchdog is None:
                self._watchdog = loop.call_at(self._started_s + SEND_TIMEOUT_S, self._check)
            try:
                await self._websocket.send_text(text)
            except asyncio.CancelledError:
                if not self._timed_out:
                    raise
                self._timed_out = False
                if self._sending is not None:
                    self._sending.uncancel()
                await close_socket(self._websocket, 1008, "client too slow")
                raise WebSocketDisconnect(1008) from None
            except RuntimeError as exc:
                # the socket was closed meanwhile (a timed-out send, the control socket's
                # lease loss): starlette refuses further sends (WebSocketDisconnected, a
                # RuntimeError); that ends this client, it is not a server error
                raise WebSocketDisconnect(1006) from exc
            finally:
                self._sending = None

    async def send_json(self, message: dict[str, Any]) -> None:
        await self.send_text(json.dumps(message, allow_nan=False))

    def _check(self) -> None:
        self._watchdog = None
        if self._sending is None:
            return  # idle: the next send arms it again
        loop = asyncio.get_running_loop()
        due_s = self._started_s + SEND_TIMEOUT_S
        if loop.time() >= due_s - 0.001:
            self._timed_out = True
            self._sending.cancel()
        else:  # a later send than the one that armed it
            self._watchdog = loop.call_at(due_s, self._check)


async def close_socket(websocket: WebSocket, code: int, reason: str = "") -> None:
    if websocket.application_state == WebSocketState.CONNECTED:
        with contextlib.suppress(RuntimeError, WebSocketDisconnect):
            await websocket.close(code, reason)


async def admit(websocket: WebSocket, socket: SocketSpec) -> ApiContext | None:
    """Accept the socket, then close it with the right code if it may not stay (the token
    its ``access`` asks for)."""
    context: ApiContext = websocket.app.state.api
    need = Role.PILOT if socket.access == "pilot" else Role.OBSERVER
    await websocket.accept()
    role = context.tokens.role_of(
        token_from(websocket.headers, websocket.query_params, websocket.cookies)
    )
    if role is None:
        await close_socket(websocket, CLOSE_UNAUTHORIZED, "missing or wrong token")
        return None
    # security.py refuses these at the handshake (403); kept for apps mounted without it
    if not origin_allowed(websocket.headers, context.settings.cors_origins):
        await close_socket(websocket, CLOSE_FORBIDDEN, "origin not allowed")
        return None
    if need is Role.PILOT and context.read_only:
        await close_socket(websocket, CLOSE_FORBIDDEN, READ_ONLY_REASON)
        return None
    if need is Role.PILOT and role is not Role.PILOT:
        await close_socket(websocket, CLOSE_FORBIDDEN, "the control socket needs the pilot token")
        return None
    return context


async def run_until_disconnect(websocket: WebSocket, *jobs: Awaitable[None]) -> None:
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
