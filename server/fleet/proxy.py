"""A REST call run by the edge that owns the vehicle: one Zenoh query to
``skyhelm/<fleet>/<edge>/api`` (fleet-spec, docs/fleet.md), answered by the edge's own app.

The query never blocks the loop: Zenoh calls back with the reply on its thread, and once
more (the handler's drop) when the query is over; the first reply, or the end of a query
that got none, resolves a Future on the loop (one hand-over per call). No reply within the
timeout is an EdgeTimeout (the route answers 504).

Query options, for a command's round trip: no consolidation (the one edge's reply is handed
over as it arrives, not held until the query is finalised), express (sent at once, not
batched), interactive-high priority (ahead of the states the edges publish), and BLOCK
congestion control (a command or its answer waits for a congested link rather than being
dropped; the edge's reply inherits the query's QoS).

Timeouts: 5 s for a call, and for an ask for control (POST .../control with "takeover" and
without "force"), which the edge holds until the holder answers or its takeover_ask_s is
over, that wait on top (call_timeout_s).
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
from skyhelm_wire.calls import CALL

QUERY_TIMEOUT_S = 5.0
# A command runs on the vehicle before the edge answers: OFFBOARD's pre-stream, the command's
# ACK with its retries and the mode's confirmation, once more when PX4 accepts but does not
# enter the mode; on a loaded edge that passes 5 s. The edge answers 504 itself when the
# vehicle is silent, so the fleet waits for that answer rather than guessing.
COMMAND_TIMEOUT_S = 15.0
QUERY_PRIORITY = zenoh.Priority.INTERACTIVE_HIGH


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
    replied: list[bool] = []  # on Zenoh's thread only: a reply came, the end needs no hop

    def settle(value: bytes | None) -> None:
        if not answer.done():
            answer.set_result(value)

    def on_reply(reply: zenoh.Reply) -> None:
        # the payload is read here, on Zenoh's thread; the first reply wins
        replied.append(True)
        ok = reply.ok
        if ok is not None:
            _on_loop(loop, settle, ok.payload.to_bytes())
            return
        error = reply.err
        message = b"" if error is None else error.payload.to_bytes()
        _on_loop(loop, _settle_error, answer, message)

    def on_done() -> None:
        # the query is over (every reply in, or its timeout): no reply means None
        if not replied:
            _on_loop(loop, settle, None)

    session.get(
        keys.api(edge),
        # called on Zenoh's own thread (both only hand a value to the loop): no Python
        # thread started for each query
        zenoh.handlers.Callback(on_reply, on_done, indirect=False),
        payload=json.dumps(request, allow_nan=False).encode(),
        timeout=timeout_s,
        target=zenoh.QueryTarget.BEST_MATCHING,
        consolidation=zenoh.ConsolidationMode.NONE,
        congestion_control=zenoh.CongestionControl.BLOCK,
        priority=QUERY_PRIORITY,
        express=True,
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


def call_timeout_s(
    method: str, rest: str, body: Any, takeover_ask_s: float, base_s: float = QUERY_TIMEOUT_S
) -> float:
    """How long the edge has to answer a call on ``.../vehicles/{id}/{rest}``: ``base_s``
    for a read, at least ``COMMAND_TIMEOUT_S`` for anything else, plus ``takeover_ask_s`` for
    an ask for control, which the edge holds that long for the holder's answer (a forced
    takeover is answered at once)."""
    asks = (
        method == "POST"
        and rest.strip("/") == CALL["acquire"].path
        and isinstance(body, dict)
        and body.get("takeover") is True
        and body.get("force") is not True
    )
    if method in ("GET", "HEAD"):
        return base_s
    writes_s = max(base_s, COMMAND_TIMEOUT_S)
    return writes_s + takeover_ask_s if asks else writes_s


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
