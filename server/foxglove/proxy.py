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

from fastapi import FastAPI, WebSocket
from websockets.typing import Subprotocol

from server.control.auth import token_from
from server.scene.proxy import LoopbackSocketProxy
from skyhelm_wire.sockets import SOCKET

SUBPROTOCOL = "foxglove.websocket.v1"
SDK_SUBPROTOCOL = "foxglove.sdk.v1"
# what a client may offer, in the order this route prefers them
ACCEPTED = (SDK_SUBPROTOCOL, SUBPROTOCOL)
PATH = SOCKET["foxglove"].url_path  # /api/v1/foxglove
WS_CLOSE_UNAUTHORIZED = 4401


class FoxgloveProxy(LoopbackSocketProxy):
    """The Foxglove server's socket at PATH."""

    # a refused socket ends in the handshake (the client sees HTTP 403)
    refuse_after_accept = False

    def mount(self, app: FastAPI) -> None:
        app.add_api_websocket_route(PATH, self.socket)

    async def socket(self, websocket: WebSocket) -> None:
        token = token_from(websocket.headers, websocket.query_params, {})
        if not self._check_token(token):
            await self.refuse(websocket, WS_CLOSE_UNAUTHORIZED, "missing or wrong token")
            return
        offered = websocket.scope.get("subprotocols", [])
        chosen = next((name for name in ACCEPTED if name in offered), None)
        if chosen is None:
            await self.refuse(websocket, 1002, f"speak {SUBPROTOCOL}")
            return
        await self.relay_upstream(
            websocket, [Subprotocol(SDK_SUBPROTOCOL)], lambda _upstream: chosen,
            "Foxglove server unavailable",
        )

