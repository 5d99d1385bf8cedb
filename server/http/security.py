"""Exposure and abuse: one ASGI middleware in front of everything (API, page, scene, sockets).

- Wrong tokens back an address off (auth_lockout.py): 429 with Retry-After while locked.
- REST control calls (any method but GET/HEAD/OPTIONS under /api/) are rate-limited per
  token (ratelimit.py): 429 with Retry-After. The control socket's messages have their own
  bucket per token (ws_control.py).
- A browser WebSocket to the API from a foreign Origin is refused at the handshake (403); so
  is a state-changing REST call from one (a cross-site form riding the session cookie).
- Security headers on every HTTP answer: a Content-Security-Policy per area (the page, the
  viser scene, the OpenAPI docs), frame-ancestors 'self', nosniff, no referrer.
- Log redaction: no log line carries a token (``token=`` values, Bearer credentials, the
  session cookie), whoever logs it (uvicorn's access and error logs, ours).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Awaitable, Callable, Iterable, Mapping, MutableMapping
from typing import Any
from urllib.parse import urlsplit

from fastapi import FastAPI
from starlette.datastructures import QueryParams
from starlette.requests import cookie_parser

from server.control.auth import TOKEN_COOKIE, TOKEN_QUERY, Role, TokenChecker, token_from
from server.http.guards import (
    SAFE_METHODS,
    Guards,
    refusal_body,
    retry_after_header,
)

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
Asgi = Callable[[Scope, Receive, Send], Awaitable[None]]

API_PATH = "/api/"
SCENE_PATH = "/scene"
DOCS_PATHS = ("/docs", "/redoc")

# The page: own scripts and styles only; map tiles may come from a tile server (https); the
# scene in an iframe of the same origin; sockets to the same origin ('self' covers ws/wss of
# the page's own host in CSP 3).
PAGE_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; "
    "img-src 'self' data: blob: https:; font-src 'self' data:; "
    "connect-src 'self'; worker-src 'self'; frame-src 'self'; media-src 'self'; "
    "object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'self'"
)
# viser's client is one inline loader script that unpacks a zstd-compressed bundle with
# WebAssembly and inserts it as inline <script>/<style>; the bundle also evaluates code at
# run time (Chromium reports a script-src 'eval' violation without 'unsafe-eval'); it draws
# with WebGL in workers. The scene's documents carry no token (the cookie is HttpOnly).
SCENE_CSP = (
    "default-src 'self'; "
    "script-src 'self' 'unsafe-inline' 'unsafe-eval' 'wasm-unsafe-eval' blob:; "
    "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; font-src 'self' data:; "
    "connect-src 'self' data: blob:; worker-src 'self' blob:; "
    "object-src 'none'; base-uri 'none'; frame-ancestors 'self'"
)
# FastAPI's /docs and /redoc load Swagger UI / ReDoc from jsDelivr with an inline script.
DOCS_CSP = (
    "default-src 'self'; script-src 'self' 'unsafe-inline' https://cdn.jsdelivr.net; "
    "style-src 'self' 'unsafe-inline' https://cdn.jsdelivr.net https://fonts.googleapis.com; "
    "font-src 'self' data: https://fonts.gstatic.com; img-src 'self' data: https:; "
    "worker-src 'self' blob:; object-src 'none'; base-uri 'none'; frame-ancestors 'self'"
)
COMMON_HEADERS = {
    "x-content-type-options": "nosniff",
    "referrer-policy": "no-referrer",
    "x-frame-options": "SAMEORIGIN",
    "cross-origin-opener-policy": "same-origin",
}


def csp_for(path: str) -> str:
    if path == SCENE_PATH or path.startswith(SCENE_PATH + "/"):
        return SCENE_CSP
    if path.startswith(DOCS_PATHS):
        return DOCS_CSP
    return PAGE_CSP


# --- log redaction ---------------------------------------------------------------------------

_SECRETS_IN_TEXT = (
    re.compile(r"((?:\btoken|" + re.escape(TOKEN_COOKIE) + r")=)[^&\s\"';,]+", re.IGNORECASE),
    re.compile(r"(\bbearer\s+)[^\s\"',]+", re.IGNORECASE),
    # the credential after the scheme word (Basic, Bearer, …) or a bare one
    re.compile(
        r"(\bauthorization[\"']?\s*[:=,]\s*[\"']?(?:[a-z]+\s+)?)[^\s\"',;]+", re.IGNORECASE
    ),
)
REDACTED = "***"


def redact(text: str) -> str:
    """The text with every token value replaced by ***."""
    for pattern in _SECRETS_IN_TEXT:
        text = pattern.sub(r"\1" + REDACTED, text)
    return text


class RedactTokens(logging.Filter):
    """Tokens travel in URLs (?token=), headers and a cookie; no log line may carry one."""

    def filter(self, record: logging.LogRecord) -> bool:
        _redact_record(record)
        return True


def _redact_record(record: logging.LogRecord) -> None:
    try:
        message = record.getMessage()
    except Exception:  # a malformed record is the logging module's to report
        return
    redacted = redact(message)
    if redacted != message:
        record.msg = redacted
        record.args = None


def install_log_redaction() -> None:
    """Redact every log record as it is made, whichever logger makes it (uvicorn logs a
    request's and a WebSocket's path with its query on uvicorn.access and uvicorn.error) and
    whichever handlers are set up; installed once per process."""
    factory = logging.getLogRecordFactory()
    if getattr(factory, "redacts_tokens", False):
        return

    def make_record(*args: Any, **kwargs: Any) -> logging.LogRecord:
        record = factory(*args, **kwargs)
        _redact_record(record)
        return record

    make_record.redacts_tokens = True  # type: ignore[attr-defined]
    logging.setLogRecordFactory(make_record)


# --- limits ----------------------------------------------------------------------------------


def origin_allowed(headers: Mapping[str, str], allowed: Iterable[str]) -> bool:
    """Browsers always send Origin on WebSockets and state-changing fetches; scripts usually
    send none. Allowed: none, the server's own host, or a configured origin."""
    origin = headers.get("origin")
    if origin is None or origin in allowed:
        return True
    return urlsplit(origin).netloc == headers.get("host")


class SecurityMiddleware:
    def __init__(
        self, app: Asgi, *, tokens: TokenChecker, guards: Guards, allowed_origins: list[str]
    ) -> None:
        self.app = app
        self.tokens = tokens
        self.guards = guards
        self.allowed_origins = list(allowed_origins)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        path: str = scope.get("path", "")
        client = scope.get("client")
        address = client[0] if client else ""
        headers = _headers(scope)
        # Only the API and the scene read tokens: a stale cookie on the static page is no guess.
        checks_token = path.startswith((API_PATH, SCENE_PATH))
        token = _token(scope, headers) if checks_token else None
        role: Role | None = None
        if token and checks_token:
            role, refusal = self.guards.admit_token(self.tokens, address, token)
            if refusal is not None:
                await _refuse(scope, receive, send, 429, refusal.reason, refusal.retry_after_s)
                return
        if not origin_allowed(headers, self.allowed_origins) and (
            (kind == "websocket" and path.startswith(API_PATH))
            or (kind == "http" and scope["method"] not in SAFE_METHODS)
        ):
            await _refuse(scope, receive, send, 403, "origin not allowed", field="Origin")
            return
        if kind == "http" and role is not None and path.startswith(API_PATH):
            refusal = self.guards.admit_call(role, scope["method"])
            if refusal is not None:
                await _refuse(scope, receive, send, 429, refusal.reason, refusal.retry_after_s)
                return
        if kind == "http":
            await self.app(scope, receive, _with_headers(send, csp_for(path)))
        else:
            await self.app(scope, receive, send)


def install_security(
    app: FastAPI, tokens: TokenChecker, guards: Guards, allowed_origins: list[str]
) -> None:
    """The middleware, outermost (added last), and the log redaction."""
    app.add_middleware(
        SecurityMiddleware, tokens=tokens, guards=guards, allowed_origins=allowed_origins
    )
    install_log_redaction()


_WANTED_HEADERS = frozenset({b"authorization", b"cookie", b"origin", b"host"})


def _headers(scope: Scope) -> dict[str, str]:
    """The few request headers the checks read (the first of each), without parsing all."""
    found: dict[str, str] = {}
    for name, value in scope.get("headers", ()):
        lower = name.lower()
        if lower in _WANTED_HEADERS and lower.decode() not in found:
            found[lower.decode()] = value.decode("latin-1")
    return found


def _token(scope: Scope, headers: dict[str, str]) -> str | None:
    """What auth.token_from finds, parsing the query and cookies only when they can hold it."""
    query: Mapping[str, str] = {}
    raw_query: bytes = scope.get("query_string", b"")
    if TOKEN_QUERY.encode() + b"=" in raw_query:
        query = QueryParams(raw_query.decode("latin-1"))
    cookies: Mapping[str, str] = {}
    cookie = headers.get("cookie", "")
    if TOKEN_COOKIE in cookie:
        cookies = cookie_parser(cookie)
    return token_from(headers, query, cookies)


_ADDED_HEADERS: dict[str, list[tuple[bytes, bytes]]] = {
    csp: [
        (name.encode(), value.encode())
        for name, value in {**COMMON_HEADERS, "content-security-policy": csp}.items()
    ]
    for csp in (PAGE_CSP, SCENE_CSP, DOCS_CSP)
}


def _with_headers(send: Send, csp: str) -> Send:
    added = _ADDED_HEADERS[csp]

    async def send_with_headers(message: Message) -> None:
        if message["type"] == "http.response.start":
            headers = list(message.get("headers", []))
            present = {name.lower() for name, _ in headers}
            headers += [(name, value) for name, value in added if name not in present]
            message["headers"] = headers
        await send(message)

    return send_with_headers


async def _refuse(
    scope: Scope,
    receive: Receive,
    send: Send,
    status: int,
    reason: str,
    retry_after_s: float | None = None,
    **cause: str,
) -> None:
    """An HTTP error answer, or for a WebSocket the same answer to its handshake (a
    client sees the status; without the ASGI extension for that, a close: 403)."""
    body = refusal_body(reason, retry_after_s, **cause)
    headers = [
        (b"content-type", b"application/json"),
        (b"content-length", str(len(body)).encode()),
    ]
    headers += [(k.encode(), v.encode()) for k, v in COMMON_HEADERS.items()]
    if retry_after_s is not None:
        headers.append((b"retry-after", retry_after_header(retry_after_s).encode()))
    if scope["type"] == "http":
        await send({"type": "http.response.start", "status": status, "headers": headers})
        await send({"type": "http.response.body", "body": body})
        return
    await receive()  # websocket.connect
    if "websocket.http.response" in scope.get("extensions", {}):
        await send({"type": "websocket.http.response.start", "status": status, "headers": headers})
        await send({"type": "websocket.http.response.body", "body": body})
    else:
        await send({"type": "websocket.close", "code": 1008, "reason": reason})
