"""The Foxglove server behind the app's port and token: ``/api/v1/foxglove``.

The SDK's server checks no token, so it listens on loopback only; this route lets a
Foxglove client elsewhere in, with the pilot or observer token in the query
(``?token=``) or a Bearer header, and relays the ``foxglove.websocket.v1`` socket frame by
frame. A missing or wrong token is refused before anything is relayed (close 4401); the
app's security middleware has by then applied its wrong-token lockout and Origin rule.

The SDK's server (0.30) names its protocol ``foxglove.sdk.v1`` in the handshake and refuses
the specification's name, ``foxglove.websocket.v1``, which clients written against the
specification (PlotJuggler, the ws-protocol libraries) offer; the messages are the same
protocol v1. This route accepts either name and speaks ``foxglove.sdk.v1`` upstream.
"""

from __future__ import annotations

from collections.abc import Callable

import websockets
from fastapi import FastAPI, WebSocket
from websockets.asyncio.client import connect
from websockets.typing import Subprotocol

from server.control.auth import token_from
from server.scene.proxy import relay

SUBPROTOCOL = "foxglove.websocket.v1"
SDK_SUBPROTOCOL = "foxglove.sdk.v1"
# what a client may offer, in the order this route prefers them
ACCEPTED = (SDK_SUBPROTOCOL, SUBPROTOCOL)
PATH = "/api/v1/foxglove"
WS_CLOSE_UNAUTHORIZED = 4401
_UPSTREAM_TIMEOUT_S = 10.0


class FoxgloveProxy:
    def __init__(self, upstream_port: Callable[[], int],
                 check_token: Callable[[str | None], bool]) -> None:
        self._upstream_port = upstream_port
        self._check_token = check_token
        self.open_sockets = 0

    def mount(self, app: FastAPI) -> None:
        app.add_api_websocket_route(PATH, self.socket)

    async def socket(self, websocket: WebSocket) -> None:
        token = token_from(websocket.headers, websocket.query_params, {})
        if not self._check_token(token):
            await websocket.close(code=WS_CLOSE_UNAUTHORIZED, reason="missing or wrong token")
            return
        offered = websocket.scope.get("subprotocols", [])
        chosen = next((name for name in ACCEPTED if name in offered), None)
        if chosen is None:
            await websocket.close(code=1002, reason=f"speak {SUBPROTOCOL}")
            return
        try:
            upstream = await connect(
                f"ws://127.0.0.1:{self._upstream_port()}",
                subprotocols=[Subprotocol(SDK_SUBPROTOCOL)],
                max_size=None, compression=None, open_timeout=_UPSTREAM_TIMEOUT_S,
            )
        except (OSError, RuntimeError, websockets.exceptions.WebSocketException, TimeoutError):
            await websocket.close(code=1011, reason="Foxglove server unavailable")
            return
        self.open_sockets += 1
        try:
            await websocket.accept(subprotocol=chosen)
            await relay(websocket, upstream)
        finally:
            self.open_sockets -= 1
            await upstream.close()

