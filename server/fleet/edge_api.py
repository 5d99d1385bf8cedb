"""The edge's api queryable: a REST call sent over Zenoh (``skyhelm/<fleet>/<edge>/api``),
run through this server's own ASGI app, so every check (token, observer read-only, lease,
rate limit, 422/409/504) is exactly REST's.

Query payload (JSON)::

    {"method": "POST", "path": "/api/v1/vehicles/1/arm", "query": "a=b",
     "headers": {"authorization": "Bearer <token>", "x-lease-id": "..."}, "body": {...}}

Reply payload (JSON): ``{"status": 200, "headers": {"content-type": ...}, "body": ...}``.

Only the caller's own authority counts: of its headers only Authorization, X-Lease-Id and
Accept reach the app; the fleet server that forwards the call adds none of its own. Only
paths under /api/v1/ are run (the fleet's own routes are not: a call is never forwarded on);
anything else answers 404, a payload that is not such an object 422. The app sees the call
as coming from the client address ``zenoh`` (its lockout and logs say so). Tokens are never
logged.

Threads: Zenoh calls back on its own thread; the payload is read there and the call handed
to the event loop, which runs it; the reply goes out from a small thread pool (a reply may
wait while the querier's link is congested; the loop never does). Every query is answered
(503 when the edge is stopping or too busy) and then dropped, so the querier never waits
for its timeout.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Awaitable, Callable, MutableMapping
from concurrent.futures import ThreadPoolExecutor
from typing import Any
from urllib.parse import unquote

import httpx
import zenoh

log = logging.getLogger(__name__)

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Asgi = Callable[
    [Scope, Callable[[], Awaitable[Message]], Callable[[Message], Awaitable[None]]],
    Awaitable[None],
]

API_PREFIX = "/api/v1/"
# routes a remote caller may not reach through an edge: another hop of the fleet
NOT_FORWARDED = ("/api/v1/fleet",)
METHODS = frozenset({"GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"})
# the caller's request headers the app gets: its token, its lease, what it accepts
REQUEST_HEADERS = frozenset({"authorization", "x-lease-id", "accept"})
# the app's answer headers the caller gets
REPLY_HEADERS = ("content-type", "retry-after", "www-authenticate", "location")
# the client address the app sees for a call that came over Zenoh
ZENOH_CLIENT = ("zenoh", 0)
# a REST call answers on its own (504 when the vehicle is silent) well within this
CALL_TIMEOUT_S = 60.0
# calls run at once; more are refused with 503 (the app's rate limit counts the rest)
MAX_IN_FLIGHT = 64
# threads that send replies (a reply may wait while the querier's link is congested)
REPLY_THREADS = 2
# a REST call's JSON is small; a larger query payload is refused before it is parsed
MAX_PAYLOAD_BYTES = 1 << 20


class CallError(Exception):
    """A query that is not a REST call this edge runs."""

    def __init__(self, status: int, reason: str, field: str | None = None) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason
        self.field = field

    def reply(self) -> dict[str, Any]:
        detail: dict[str, Any] = {"reason": self.reason}
        if self.field is not None:
            detail["field"] = self.field
        return _json_reply(self.status, {"detail": detail})


def _json_reply(status: int, body: Any) -> dict[str, Any]:
    return {"status": status, "headers": {"content-type": "application/json"}, "body": body}


def parse_call(data: bytes | None) -> dict[str, Any]:
    """The query payload as a checked call (method, path, query, headers, body)."""
    if not data:
        raise CallError(422, "the query carries no payload", "payload")
    if len(data) > MAX_PAYLOAD_BYTES:
        raise CallError(413, f"the query payload exceeds {MAX_PAYLOAD_BYTES} bytes", "payload")
    try:
        call = json.loads(data)
    except ValueError:  # also bad UTF-8
        raise CallError(422, "the query payload is not JSON", "payload") from None
    if not isinstance(call, dict):
        raise CallError(422, "the query payload is not a JSON object", "payload")
    method = call.get("method")
    if not isinstance(method, str) or method.upper() not in METHODS:
        raise CallError(422, f"method must be one of {sorted(METHODS)}", "method")
    path = call.get("path")
    if not isinstance(path, str):
        raise CallError(422, "path must be a string", "path")
    check_path(path)
    query = call.get("query")
    if query is not None and not isinstance(query, str):
        raise CallError(422, "query must be a string or null", "query")
    headers = call.get("headers") or {}
    if not isinstance(headers, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in headers.items()
    ):
        raise CallError(422, "headers must be an object of strings", "headers")
    return {
        "method": method.upper(),
        "path": path,
        "query": query or "",
        "headers": {k.lower(): v for k, v in headers.items() if k.lower() in REQUEST_HEADERS},
        "body": call.get("body"),
    }


def check_path(path: str) -> None:
    """Only the API's own paths, without dot segments, query or fragment: else 404."""
    plain = unquote(path)
    segments = plain.split("/")
    if (
        not path.startswith(API_PREFIX)
        or any(part in (".", "..") for part in segments)
        or "?" in path
        or "#" in path
        or any(ord(c) < 0x21 for c in plain)
        or plain.startswith(NOT_FORWARDED)
    ):
        raise CallError(404, f"not an API path this edge runs: {path[:200]!r}", "path")


class EdgeApi:
    """Runs calls through the app; answers queries of the api queryable."""

    def __init__(
        self,
        app: Asgi,
        reply_key: str,
        *,
        call_timeout_s: float = CALL_TIMEOUT_S,
        max_in_flight: int = MAX_IN_FLIGHT,
    ) -> None:
        self.reply_key = reply_key
        self.call_timeout_s = call_timeout_s
        self.max_in_flight = max_in_flight
        self.calls = 0
        self.refused = 0  # malformed or refused before the app saw them
        # the transport without a client: httpx's client logs every URL, query (and so a
        # token in it) included
        self._transport = httpx.ASGITransport(
            app=app, raise_app_exceptions=False, client=ZENOH_CLIENT
        )
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tasks: set[asyncio.Task[None]] = set()
        self._running = 0
        self._closing = False
        self._replies = ThreadPoolExecutor(REPLY_THREADS, thread_name_prefix="zenoh-reply")

    def bind(self) -> None:
        """Remember the loop calls are handed to (call on the loop, before declaring)."""
        self._loop = asyncio.get_running_loop()

    async def close(self) -> None:
        """Answer calls still running with 503, then close the transport."""
        self._closing = True
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await self._transport.aclose()
        await asyncio.to_thread(self._replies.shutdown)

    async def run(self, data: bytes | None) -> dict[str, Any]:
        """The reply payload for a query payload: the app's answer, or why not."""
        try:
            call = parse_call(data)
        except CallError as exc:
            self.refused += 1
            return exc.reply()
        self.calls += 1
        headers = dict(call["headers"])
        content: bytes | None = None
        if call["body"] is not None:
            try:
                content = json.dumps(call["body"], allow_nan=False).encode()
            except ValueError:
                return CallError(422, "body: numbers must be finite", "body").reply()
            headers["content-type"] = "application/json"
        url = "http://edge" + call["path"] + (f"?{call['query']}" if call["query"] else "")
        request = httpx.Request(call["method"], url, headers=headers, content=content)
        try:
            async with asyncio.timeout(self.call_timeout_s):
                response = await self._transport.handle_async_request(request)
                await response.aread()
        except TimeoutError:
            reason = f"the call did not finish within {self.call_timeout_s:g} s"
            return CallError(504, reason).reply()
        log.debug("zenoh call %s %s: %d", call["method"], call["path"], response.status_code)
        return {
            "status": response.status_code,
            "headers": {
                name: response.headers[name] for name in REPLY_HEADERS if name in response.headers
            },
            "body": _body(response),
        }

    # --- on Zenoh's thread ---------------------------------------------------------------

    def on_query(self, query: zenoh.Query) -> None:
        payload = query.payload
        data = payload.to_bytes() if payload is not None else None
        loop = self._loop
        if loop is not None and not self._closing:
            with contextlib.suppress(RuntimeError):  # the loop closed: refused below
                loop.call_soon_threadsafe(self._begin, query, data)
                return
        send_reply(query, self.reply_key, _stopping())

    # --- on the loop ---------------------------------------------------------------------

    def _begin(self, query: zenoh.Query, data: bytes | None) -> None:
        refusal: dict[str, Any] | None = None
        if self._closing:
            refusal = _stopping()
        elif self._running >= self.max_in_flight:
            self.refused += 1
            reason = f"the edge is running {self.max_in_flight} calls; try again"
            refusal = CallError(503, reason).reply()
        task = asyncio.create_task(self._answer(query, data, refusal), name="zenoh-api-call")
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _answer(
        self, query: zenoh.Query, data: bytes | None, refusal: dict[str, Any] | None
    ) -> None:
        reply = refusal
        if reply is None:
            self._running += 1
            try:
                reply = await self.run(data)
            except asyncio.CancelledError:
                reply = _stopping()  # answered all the same, below
            except Exception:  # the client failed, not the app (its errors are answers)
                log.exception("zenoh api call failed")
                reply = CallError(500, "the edge failed to run the call").reply()
            finally:
                self._running -= 1
        # a reply may wait for a congested link: never on the loop
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self._replies, send_reply, query, self.reply_key, reply)


def send_reply(query: zenoh.Query, key: str, reply: dict[str, Any]) -> None:
    """Answer a query and drop it (finalising it for the querier); errors only logged."""
    try:
        query.reply(
            key, json.dumps(reply, allow_nan=False).encode(),
            encoding=zenoh.Encoding.APPLICATION_JSON,
        )
    except zenoh.ZError as exc:  # the session closed, or the querier gave up
        log.debug("zenoh api reply not sent: %s", exc)
    finally:
        with contextlib.suppress(zenoh.ZError):
            query.drop()  # type: ignore[no-untyped-call]


def _stopping() -> dict[str, Any]:
    return CallError(503, "the edge is stopping").reply()


def _body(response: httpx.Response) -> Any:
    if not response.content:
        return None
    try:
        return response.json()
    except ValueError:
        return response.text
