"""One HTTP request run straight through an ASGI app in-process: a minimal scope, a receive
that hands over the body once and then waits for the answer to be complete (so a route
watching for its client to leave sees it stay), a send that collects the answer.

What httpx.ASGITransport does for a test client, without its request/response objects,
stream wrappers and anyio events: the edge runs every REST call that comes over Zenoh this
way (edge_api.py). The app's own errors are answers (its 500), never raised here; a call
that raised before it answered is a 500 with no body.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, MutableMapping
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import unquote

log = logging.getLogger(__name__)

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Asgi = Callable[
    [Scope, Callable[[], Awaitable[Message]], Callable[[Message], Awaitable[None]]],
    Awaitable[None],
]

HOST = b"edge"


@dataclass
class AsgiAnswer:
    status: int = 500
    headers: dict[str, str] = field(default_factory=dict)
    body: bytes = b""


async def call_app(
    app: Asgi,
    method: str,
    path: str,
    query: str,
    headers: dict[str, str],
    body: bytes,
    client: tuple[str, int],
) -> AsgiAnswer:
    """Run ``method path?query`` with ``headers`` (lower-case names) and ``body`` through
    ``app``; its status, headers (lower-case names, the last of repeated ones) and body."""
    raw_headers = [(b"host", HOST)]
    raw_headers += [(k.encode("latin-1"), v.encode("latin-1")) for k, v in headers.items()]
    if body:
        raw_headers.append((b"content-length", str(len(body)).encode()))
    scope: Scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": method,
        "scheme": "http",
        "path": unquote(path),
        "raw_path": path.encode("latin-1"),
        "query_string": query.encode("latin-1"),
        "root_path": "",
        "headers": raw_headers,
        "client": client,
        "server": ("edge", 80),
        "extensions": {},
    }
    answer = AsgiAnswer()
    chunks: list[bytes] = []
    complete = asyncio.Event()
    body_sent = False

    async def receive() -> Message:
        nonlocal body_sent
        if not body_sent:
            body_sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        await complete.wait()  # the caller stays until the answer is whole
        return {"type": "http.disconnect"}

    async def send(message: Message) -> None:
        kind = message["type"]
        if kind == "http.response.start":
            answer.status = int(message["status"])
            answer.headers = {
                bytes(k).decode("latin-1").lower(): bytes(v).decode("latin-1")
                for k, v in message.get("headers", ())
            }
        elif kind == "http.response.body":
            chunks.append(bytes(message.get("body", b"")))
            if not message.get("more_body", False):
                complete.set()

    try:
        await app(scope, receive, send)
    except Exception:  # the app's error handler answered 500 (or nothing) already
        log.debug("the app raised running %s %s", method, path, exc_info=True)
    finally:
        complete.set()
    answer.body = b"".join(chunks)
    return answer
