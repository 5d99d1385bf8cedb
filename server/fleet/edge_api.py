"""The edge's api queryable: a REST call sent over Zenoh (``skyhelm/<fleet>/<edge>/api``),
run on this server's control core by edge_calls.py with REST's checks and functions, so
every check (token, observer read-only, lease, rate limit, 422/409/504) is exactly REST's.

Query payload (JSON)::

    {"method": "POST", "path": "/api/v1/vehicles/1/arm", "query": "a=b",
     "headers": {"authorization": "Bearer <token>", "x-lease-id": "..."}, "body": {...}}

Reply payload (JSON): ``{"status": 200, "headers": {"content-type": ...}, "body": ...}``.

Only the caller's own authority counts: of its headers only Authorization and X-Lease-Id
are read; the fleet server that forwards the call adds none of its own. Only the calls
under /api/v1/vehicles/{id} are run (the fleet's own routes are not: a call is never
forwarded on); anything else answers 404, a payload that is not such an object 422. The
call counts as coming from the address ``zenoh`` (the lockout and logs say so). Tokens are
never logged.

The answer's JSON goes into the reply as it was encoded (not decoded and encoded again).

Threads: Zenoh calls back on its callback thread; the payload is read there and the call
handed to the event loop, which runs it; the reply is handed to one reply thread and the
loop goes on (a reply may wait while the querier's link is congested; the loop never does).
Every query is answered (503 when the edge is stopping or too busy) and then dropped, so
the querier never waits for its timeout.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import queue
import threading
from typing import Any
from urllib.parse import unquote

import zenoh

from server.fleet.edge_calls import EdgeCalls
from server.http.errors import non_finite_field
from server.http.vehicle_calls import Reply
from skyhelm_wire.calls import API_PREFIX as API

log = logging.getLogger(__name__)

API_PREFIX = f"{API}/"
# routes a remote caller may not reach through an edge: another hop of the fleet
NOT_FORWARDED = (f"{API}/fleet",)
METHODS = frozenset({"GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"})
# the caller's request headers that are read: its token, its lease
REQUEST_HEADERS = frozenset({"authorization", "x-lease-id"})
# the answer's headers the caller gets
REPLY_HEADERS = ("content-type", "retry-after", "www-authenticate")
# a REST call answers on its own (504 when the vehicle is silent) well within this
CALL_TIMEOUT_S = 60.0
# calls run at once; more are refused with 503 (the rate limit counts the rest)
MAX_IN_FLIGHT = 64
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
    """Runs calls on the control core; answers queries of the api queryable."""

    def __init__(
        self,
        calls: EdgeCalls,
        reply_key: str,
        *,
        call_timeout_s: float = CALL_TIMEOUT_S,
        max_in_flight: int = MAX_IN_FLIGHT,
    ) -> None:
        self.reply_key = reply_key
        self.call_timeout_s = call_timeout_s
        self.max_in_flight = max_in_flight
        self.calls = 0
        self.refused = 0  # malformed or refused before they ran
        self._calls = calls
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tasks: set[asyncio.Task[None]] = set()
        self._running = 0
        self._closing = False
        self._replies = Replier()

    def bind(self) -> None:
        """Remember the loop calls are handed to (call on the loop, before declaring)."""
        self._loop = asyncio.get_running_loop()

    async def close(self) -> None:
        """Answer calls still running with 503; stop the reply threads."""
        self._closing = True
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await asyncio.to_thread(self._replies.close)

    async def run(self, data: bytes | None) -> dict[str, Any]:
        """The reply payload for a query payload, decoded (see encoded_reply)."""
        reply: dict[str, Any] = json.loads(await self.encoded_reply(data))
        return reply

    async def encoded_reply(self, data: bytes | None) -> bytes:
        """The reply payload for a query payload: the app's answer, or why not."""
        try:
            call = parse_call(data)
        except CallError as exc:
            self.refused += 1
            return _encode(exc.reply())
        self.calls += 1
        field = non_finite_field(call["body"])
        if field is not None:
            reason = "body: numbers must be finite"
            return _encode(CallError(422, reason, "body").reply())
        try:
            async with asyncio.timeout(self.call_timeout_s):
                answer = await self._calls.run(
                    call["method"], unquote(call["path"]), call["query"], call["headers"],
                    call["body"],
                )  # fmt: skip
        except TimeoutError:
            reason = f"the call did not finish within {self.call_timeout_s:g} s"
            return _encode(CallError(504, reason).reply())
        log.debug("zenoh call %s %s: %d", call["method"], call["path"], answer.status)
        return encode_answer(answer)

    # --- on Zenoh's thread ---------------------------------------------------------------

    def on_query(self, query: zenoh.Query) -> None:
        payload = query.payload
        data = payload.to_bytes() if payload is not None else None
        loop = self._loop
        if loop is not None and not self._closing:
            with contextlib.suppress(RuntimeError):  # the loop closed: refused below
                loop.call_soon_threadsafe(self._begin, query, data)
                return
        self._replies.send(query, self.reply_key, _encode(_stopping()))

    # --- on the loop ---------------------------------------------------------------------

    def _begin(self, query: zenoh.Query, data: bytes | None) -> None:
        refusal: bytes | None = None
        if self._closing:
            refusal = _encode(_stopping())
        elif self._running >= self.max_in_flight:
            self.refused += 1
            reason = f"the edge is running {self.max_in_flight} calls; try again"
            refusal = _encode(CallError(503, reason).reply())
        task = asyncio.create_task(self._answer(query, data, refusal), name="zenoh-api-call")
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _answer(self, query: zenoh.Query, data: bytes | None, refusal: bytes | None) -> None:
        reply = refusal
        if reply is None:
            self._running += 1
            try:
                reply = await self.encoded_reply(data)
            except asyncio.CancelledError:
                reply = _encode(_stopping())  # answered all the same, below
            except Exception:  # the edge failed, not the app (its errors are answers)
                log.exception("zenoh api call failed")
                reply = _encode(CallError(500, "the edge failed to run the call").reply())
            finally:
                self._running -= 1
        # a reply may wait for a congested link: never on the loop, and nothing comes back
        self._replies.send(query, self.reply_key, reply)


class Replier:
    """One thread that sends replies in order: the loop hands a reply over and goes on (a
    reply may wait while the querier's link is congested; the loop never does). A reply
    handed over after close() is sent at once on the caller's thread."""

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[tuple[zenoh.Query, str, bytes] | None] = (
            queue.SimpleQueue()
        )
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="zenoh-reply", daemon=True)
        self._thread.start()

    def send(self, query: zenoh.Query, key: str, reply: bytes) -> None:
        if self._closed:
            send_reply(query, key, reply)
        else:
            self._queue.put((query, key, reply))

    def close(self) -> None:
        """Send what is queued, then stop the thread (blocks: call off the loop)."""
        self._closed = True
        self._queue.put(None)
        self._thread.join()

    def _run(self) -> None:
        while (item := self._queue.get()) is not None:
            try:
                send_reply(*item)
            except Exception:  # never the end of the thread: the next replies still go out
                log.exception("zenoh api reply failed")


def send_reply(query: zenoh.Query, key: str, reply: bytes) -> None:
    """Answer a query and drop it (finalising it for the querier); errors only logged."""
    try:
        query.reply(key, reply, encoding=zenoh.Encoding.APPLICATION_JSON)
    except zenoh.ZError as exc:  # the session closed, or the querier gave up
        log.debug("zenoh api reply not sent: %s", exc)
    finally:
        with contextlib.suppress(zenoh.ZError):
            query.drop()  # type: ignore[no-untyped-call]


def _stopping() -> dict[str, Any]:
    return CallError(503, "the edge is stopping").reply()


def _encode(reply: dict[str, Any]) -> bytes:
    return json.dumps(reply, allow_nan=False).encode()


def encode_answer(answer: Reply) -> bytes:
    """The reply payload for an answer: its status, the headers a caller may act on, and
    its JSON body as encoded (none: null)."""
    headers = {name: answer.headers[name] for name in REPLY_HEADERS if name in answer.headers}
    head = json.dumps({"status": answer.status, "headers": headers})
    encoded_body = answer.body.strip() or b"null"
    # {"status": .., "headers": {..}, "body": <body>}: the head without its closing brace
    return head[:-1].encode() + b', "body": ' + encoded_body + b"}"
