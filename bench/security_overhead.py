"""What the security layer costs per request and per log line: SecurityMiddleware (token
lookup, lockout, Origin, the control bucket, headers) around a bare ASGI app, called
directly (no sockets), against the bare app; and the log redaction per record.

    PYTHONPATH=$PWD .venv/bin/python -m bench.security_overhead
"""

from __future__ import annotations

import asyncio
import logging
import os
import time
from typing import Any

from bench._markdown import ratio, table
from bench._report import Section
from bench._results import machine_info, write_results
from server.control.auth import TokenChecker
from server.control.auth_lockout import Lockout
from server.control.ratelimit import RateLimiter
from server.http.guards import Guards
from server.http.security import SecurityMiddleware, install_log_redaction

TOKEN = "bench-token-0123456789"
REQUESTS = 20_000
LOG_LINES = 20_000


async def bare(scope: Any, receive: Any, send: Any) -> None:
    await send({"type": "http.response.start", "status": 200, "headers": []})
    await send({"type": "http.response.body", "body": b"{}"})


def scope(method: str, path: str) -> dict[str, Any]:
    return {
        "type": "http",
        "method": method,
        "path": path,
        "query_string": b"",
        "headers": [(b"authorization", f"Bearer {TOKEN}".encode()), (b"host", b"bench")],
        "client": ("127.0.0.1", 5000),
    }


async def per_request_us(app: Any, method: str, path: str) -> float:
    async def receive() -> dict[str, Any]:
        return {"type": "http.request", "body": b""}

    async def send(message: Any) -> None:
        return None

    request = scope(method, path)
    started = time.perf_counter()
    for _ in range(REQUESTS):
        await app(dict(request), receive, send)
    return (time.perf_counter() - started) / REQUESTS * 1e6


def main() -> None:
    load = os.getloadavg()
    guards = Guards(
        control=RateLimiter(1e9, 1e9),  # never refuses: the cost, not the limit
        ws_messages=RateLimiter(1e9, 1e9),
        lockout=Lockout(),
        ws_close_after=200,
    )
    guarded = SecurityMiddleware(
        bare, tokens=TokenChecker(TOKEN, "observer-0123456789"), guards=guards, allowed_origins=[]
    )
    figures: dict[str, Any] = {}
    figures["bare_read_us"] = asyncio.run(per_request_us(bare, "GET", "/api/v1/vehicles"))
    figures["guarded_read_us"] = asyncio.run(per_request_us(guarded, "GET", "/api/v1/vehicles"))
    figures["guarded_control_us"] = asyncio.run(
        per_request_us(guarded, "PUT", "/api/v1/vehicles/1/setpoint")
    )
    figures["middleware_overhead_us"] = figures["guarded_control_us"] - figures["bare_read_us"]

    logger = logging.getLogger("bench.redaction")
    logger.addHandler(logging.NullHandler())
    logger.propagate = False
    logger.setLevel(logging.INFO)

    def log_us() -> float:
        started = time.perf_counter()
        for i in range(LOG_LINES):
            logger.info('%s - "GET /api/v1/vehicles?token=%s&n=%d HTTP/1.1" 200', "ip", TOKEN, i)
        return (time.perf_counter() - started) / LOG_LINES * 1e6

    figures["log_record_us"] = log_us()
    install_log_redaction()
    figures["log_record_redacted_us"] = log_us()
    for name, value in figures.items():
        print(f"{name:28s} {value:8.2f} µs")
    write_results(
        "security_overhead",
        {"requests": REQUESTS, "log_lines": LOG_LINES, **figures, "machine": machine_info(load)},
    )


if __name__ == "__main__":
    main()


def report(result: dict[str, Any]) -> Section | None:
    """The security layer's cost per request and per log line, as ratios to the bare paths."""
    rows = [
        ["bare ASGI app, GET", f"{result['bare_read_us']:.1f}", "1.00×"],
        ["SecurityMiddleware, GET (observer path)", f"{result['guarded_read_us']:.1f}",
         ratio(result["guarded_read_us"], result["bare_read_us"])],
        ["SecurityMiddleware, PUT setpoint (control bucket)",
         f"{result['guarded_control_us']:.1f}",
         ratio(result["guarded_control_us"], result["bare_read_us"])],
        ["log record", f"{result['log_record_us']:.1f}", "1.00×"],
        ["log record with token redaction", f"{result['log_record_redacted_us']:.1f}",
         ratio(result["log_record_redacted_us"], result["log_record_us"])],
    ]
    markdown = (
        f"The middleware adds {result['middleware_overhead_us']:.0f} µs to a control request "
        f"(called directly, no sockets; {result['requests']} requests each): at a 50 Hz "
        f"setpoint stream that is {result['middleware_overhead_us'] * 50 / 1e4:.2f} % of one "
        f"core. Redaction makes a log record "
        f"{ratio(result['log_record_redacted_us'], result['log_record_us'])} as costly.\n\n"
        + table(["path", "µs per call", "vs bare"], rows))
    return Section("Security layer overhead", 90, markdown)
