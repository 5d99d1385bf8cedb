"""HTTP and WebSocket proxy from the app's port to viser's loopback server, behind the token."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from functools import cache
from pathlib import Path

import websockets
from fastapi import FastAPI, Request, WebSocket
from fastapi.responses import RedirectResponse, Response
from starlette.websockets import WebSocketDisconnect
from websockets.asyncio.client import ClientConnection, connect
from websockets.typing import Subprotocol

from .tokens import TOKEN_COOKIE, origin_matches_host, token_from_request

WS_CLOSE_UNAUTHORIZED = 4401
WS_CLOSE_FORBIDDEN_ORIGIN = 4403
_UPSTREAM_TIMEOUT_S = 10.0
_PASSED_HEADERS = ("content-type", "content-encoding", "cache-control")
# The script that paces the client's frames (pace.js: why and how), put first in the
# <head> of viser's page so it runs before viser's own scripts.
_HEAD = b"<head>"


@cache
def pace_script() -> bytes:
    return b"<script>" + Path(__file__).with_name("pace.js").read_bytes() + b"</script>"


def with_pace_script(body: bytes) -> bytes:
    """viser's page with pace.js first in its head (the page as it was without a head)."""
    at = body.find(_HEAD)
    if at < 0:
        return body
    at += len(_HEAD)
    return body[:at] + pace_script() + body[at:]


async def fetch_upstream(
    port: int, path: str, accept_encoding: str | None
) -> tuple[int, dict[str, str], bytes]:
    """One plain HTTP/1.1 GET to viser's server (which closes the connection after answering)."""
    reader, writer = await asyncio.wait_for(
        asyncio.open_connection("127.0.0.1", port), _UPSTREAM_TIMEOUT_S
    )
    try:
        lines = [f"GET {path} HTTP/1.1", f"Host: 127.0.0.1:{port}", "Connection: close"]
        if accept_encoding:
            lines.append(f"Accept-Encoding: {accept_encoding}")
        writer.write(("\r\n".join(lines) + "\r\n\r\n").encode("latin-1"))
        await writer.drain()
        head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), _UPSTREAM_TIMEOUT_S)
        status_line, *header_lines = head.decode("latin-1").split("\r\n")
        status = int(status_line.split(" ", 2)[1])
        headers: dict[str, str] = {}
        for line in header_lines:
            name, sep, value = line.partition(":")
            if sep:
                headers[name.strip().lower()] = value.strip()
        length = headers.get("content-length")
        if length is not None:
            body = await asyncio.wait_for(reader.readexactly(int(length)), _UPSTREAM_TIMEOUT_S)
        else:
            body = await asyncio.wait_for(reader.read(), _UPSTREAM_TIMEOUT_S)
        return status, headers, body
    finally:
        writer.close()
        with contextlib.suppress(OSError):
            await writer.wait_closed()


class LoopbackSocketProxy:
    """Sockets relayed, behind the token, to a server that listens on loopback only."""

    # A refused socket is accepted first, so its close code and reason reach the client;
    # False: closed during the handshake, which the client sees as a refused upgrade.
    refuse_after_accept = True

    def __init__(self, upstream_port: Callable[[], int],
                 check_token: Callable[[str | None], bool]) -> None:
        self._upstream_port = upstream_port
        self._check_token = check_token
        self.open_sockets = 0

    async def refuse(self, websocket: WebSocket, code: int, reason: str) -> None:
        if self.refuse_after_accept:
            await websocket.accept()
        await websocket.close(code=code, reason=reason)

    async def relay_upstream(
        self,
        websocket: WebSocket,
        offered: list[Subprotocol] | None,
        subprotocol: Callable[[ClientConnection], str | None],
        unavailable: str,
    ) -> None:
        """Open the upstream socket offering ``offered``, accept the client's with the
        subprotocol ``subprotocol`` names, and relay until either side closes."""
        try:
            upstream = await connect(
                f"ws://127.0.0.1:{self._upstream_port()}", subprotocols=offered,
                max_size=None, compression=None, open_timeout=_UPSTREAM_TIMEOUT_S,
            )
        except (OSError, RuntimeError, websockets.exceptions.WebSocketException, TimeoutError):
            await self.refuse(websocket, 1011, unavailable)
            return
        self.open_sockets += 1
        try:
            await websocket.accept(subprotocol=subprotocol(upstream))
            await relay(websocket, upstream)
        finally:
            self.open_sockets -= 1
            await upstream.close()


class SceneProxy(LoopbackSocketProxy):
    """Routes under `path`: the viser client page, its socket, and the small scene API."""

    def authorised(self, request: Request | WebSocket) -> bool:
        token = token_from_request(request.query_params, request.cookies, request.headers)
        return self._check_token(token)

    async def page(self, request: Request) -> Response:
        if not self.authorised(request):
            return Response("missing or wrong token", status_code=401)
        asset = str(request.path_params.get("asset", ""))
        # the client's page itself is asked for plain, to put the pacing script in it
        is_page = asset in ("", "index.html")
        status, headers, body = await fetch_upstream(
            self._upstream_port(), "/" + asset,
            None if is_page else request.headers.get("accept-encoding"),
        )
        passed = {k: v for k, v in headers.items() if k in _PASSED_HEADERS}
        if is_page and status == 200 and headers.get("content-encoding", "identity") == "identity":
            body = with_pace_script(body)
        passed["cache-control"] = "no-store"
        response = Response(body, status_code=status, headers=passed)
        token = request.query_params.get("token")
        if token:
            # The viser client opens its socket on the page's own path without the query,
            # so it can carry the token only as a cookie scoped to the scene.
            response.set_cookie(
                TOKEN_COOKIE, token, path=self._cookie_path(request), httponly=True,
                samesite="strict",
            )
        return response

    @staticmethod
    def _cookie_path(request: Request) -> str:
        return "/" + request.url.path.strip("/").split("/", 1)[0]

    async def socket(self, websocket: WebSocket) -> None:
        if not self.authorised(websocket):
            await self.refuse(websocket, WS_CLOSE_UNAUTHORIZED, "missing or wrong token")
            return
        if not origin_matches_host(websocket.headers):
            await self.refuse(websocket, WS_CLOSE_FORBIDDEN_ORIGIN, "cross-origin")
            return
        offered = [Subprotocol(p) for p in websocket.scope.get("subprotocols", [])]
        await self.relay_upstream(
            websocket, offered or None, lambda upstream: upstream.subprotocol,
            "scene server unavailable",
        )

    def mount(self, app: FastAPI, path: str, api: dict[str, Callable[[], object]]) -> None:
        base = "/" + path.strip("/")
        for name, getter in api.items():
            app.add_api_route(f"{base}/api/{name}", self._api_endpoint(getter),
                              methods=["GET"], include_in_schema=False)

        async def to_slash(request: Request) -> Response:
            query = f"?{request.url.query}" if request.url.query else ""
            return RedirectResponse(f"{base}/{query}", status_code=307)

        app.add_api_route(base, to_slash, methods=["GET"], include_in_schema=False)
        app.add_api_route(f"{base}/{{asset:path}}", self.page, methods=["GET"],
                          include_in_schema=False)
        app.add_api_websocket_route(base, self.socket)
        app.add_api_websocket_route(f"{base}/", self.socket)

    def _api_endpoint(self, getter: Callable[[], object]) -> Callable[[Request], object]:
        async def endpoint(request: Request) -> object:
            if not self.authorised(request):
                return Response('{"detail": "missing or wrong token"}', status_code=401,
                                media_type="application/json")
            return getter()

        return endpoint


async def relay(websocket: WebSocket, upstream: ClientConnection) -> None:
    """Copy frames both ways until either side closes; the other side is closed after it
    (the scene's socket, and the Foxglove server's in server.foxglove.proxy)."""

    async def browser_to_viser() -> None:
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return
            data = message.get("bytes")
            await upstream.send(data if data is not None else message.get("text") or "")

    async def viser_to_browser() -> None:
        async for data in upstream:
            if isinstance(data, bytes):
                await websocket.send_bytes(data)
            else:
                await websocket.send_text(data)

    tasks = [asyncio.create_task(browser_to_viser()), asyncio.create_task(viser_to_browser())]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(
                asyncio.CancelledError, WebSocketDisconnect, RuntimeError,
                websockets.exceptions.ConnectionClosed,
            ):
                await task
        with contextlib.suppress(RuntimeError, WebSocketDisconnect):
            await websocket.close()
