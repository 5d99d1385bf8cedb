"""A REST call run by the edge that owns the vehicle: one Zenoh query to
``skyhelm/<fleet>/<edge>/api`` (fleet-spec, docs/fleet.md), answered by the edge's own app.

The query never blocks the loop: Zenoh calls back with the reply on its thread, and once
more (the handler's drop) when the query is over; both resolve a Future on the loop. No
reply within the timeout is an EdgeTimeout (the route answers 504).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh

from server.fleet.keys import FleetKeys

QUERY_TIMEOUT_S = 5.0


class EdgeTimeout(Exception):
    """The edge did not answer in time (gone, partitioned, or too slow)."""


class EdgeReplyError(Exception):
    """The edge's Zenoh layer answered with an error instead of a REST answer."""


@dataclass(frozen=True)
class EdgeAnswer:
    status: int
    headers: dict[str, str]
    body: Any


async def edge_call(
    session: zenoh.Session,
    keys: FleetKeys,
    edge: str,
    request: dict[str, Any],
    timeout_s: float = QUERY_TIMEOUT_S,
) -> EdgeAnswer:
    """Send ``request`` (``{"method", "path", "query", "headers", "body"}``) to the edge's
    api queryable; its answer, or EdgeTimeout / EdgeReplyError."""
    loop = asyncio.get_running_loop()
    answer: asyncio.Future[bytes | None] = loop.create_future()

    def settle(value: bytes | None) -> None:
        if not answer.done():
            answer.set_result(value)

    def on_reply(reply: zenoh.Reply) -> None:
        # the payload is read here, on Zenoh's thread; the first reply wins
        ok = reply.ok
        if ok is not None:
            _on_loop(loop, settle, ok.payload.to_bytes())
            return
        error = reply.err
        message = b"" if error is None else error.payload.to_bytes()
        _on_loop(loop, _settle_error, answer, message)

    def on_done() -> None:
        # the query is over (every reply in, or its timeout): no reply means None
        _on_loop(loop, settle, None)

    session.get(
        keys.api(edge),
        zenoh.handlers.Callback(on_reply, on_done),
        payload=json.dumps(request, allow_nan=False).encode(),
        timeout=timeout_s,
        target=zenoh.QueryTarget.BEST_MATCHING,
    )
    try:
        # Zenoh's own timeout ends the query; this one only guards against a lost drop
        async with asyncio.timeout(timeout_s + 2.0):
            data = await answer
    except TimeoutError:
        raise EdgeTimeout(f"edge {edge} did not answer within {timeout_s:g} s") from None
    if data is None:
        raise EdgeTimeout(f"edge {edge} did not answer within {timeout_s:g} s")
    return parse_answer(edge, data)


def _on_loop(loop: asyncio.AbstractEventLoop, call: Callable[..., None], *args: Any) -> None:
    with contextlib.suppress(RuntimeError):  # the loop closed meanwhile: nobody waits
        loop.call_soon_threadsafe(call, *args)


def _settle_error(answer: asyncio.Future[Any], message: bytes) -> None:
    if not answer.done():
        text = message.decode("utf-8", "replace")[:200] or "no reason given"
        answer.set_exception(EdgeReplyError(text))


def parse_answer(edge: str, data: bytes) -> EdgeAnswer:
    """The edge's reply payload: ``{"status", "headers", "body"}``."""
    try:
        reply = json.loads(data)
        status = int(reply["status"])
        headers = reply.get("headers") or {}
        if not isinstance(headers, dict) or not 100 <= status <= 599:
            raise ValueError("bad status or headers")
    except (ValueError, KeyError, TypeError) as exc:
        raise EdgeReplyError(f"edge {edge} sent a malformed answer: {exc}") from None
    return EdgeAnswer(
        status,
        {str(k).lower(): str(v) for k, v in headers.items() if v is not None},
        reply.get("body"),
    )
