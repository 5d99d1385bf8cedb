"""Waiting in tests: for a condition, never for a fixed time.

Integration tests talk to real processes and sockets, so they wait until what they expect
has happened, with a timeout that only bounds a failing run. The poll interval is how
often the condition is looked at, not how long anything takes.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import TypeVar

T = TypeVar("T")

# Conditions here are cheap reads of in-process state; 5 ms keeps a passing wait short.
POLL_S = 0.005


async def wait_for(
    condition: Callable[[], object],
    timeout_s: float = 5.0,
    what: str = "condition",
    *,
    poll_s: float = POLL_S,
) -> float:
    """Poll ``condition`` until it is true; the loop time that took. Fails after
    ``timeout_s``."""
    loop = asyncio.get_running_loop()
    start = loop.time()
    while not condition():
        if loop.time() - start > timeout_s:
            raise AssertionError(f"{what} not met within {timeout_s} s")
        await asyncio.sleep(poll_s)
    return loop.time() - start


async def eventually(
    probe: Callable[[], Awaitable[T]], timeout_s: float, what: str, poll_s: float = 0.05
) -> T:
    """Await ``probe()`` until it returns something truthy, and return that. Fails after
    ``timeout_s`` with the last value seen."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    last: T | None = None
    while loop.time() < deadline:
        last = await probe()
        if last:
            return last
        await asyncio.sleep(poll_s)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what} (last: {last!r})")


async def holds_for(
    condition: Callable[[], object], duration_s: float, what: str, *, poll_s: float = POLL_S
) -> None:
    """Check that ``condition`` stays true for ``duration_s``: for "nothing more happens"
    claims, where no event can say that it did not. Fails the moment it is false."""
    loop = asyncio.get_running_loop()
    end = loop.time() + duration_s
    while True:
        assert condition(), f"{what} stopped holding"
        if loop.time() >= end:
            return
        await asyncio.sleep(min(poll_s, max(0.0, end - loop.time())))


def wait_for_blocking(
    what: str, check: Callable[[], T], timeout_s: float, every_s: float = 0.1
) -> T:
    """Call ``check()`` until it returns something truthy, and return that; for code with
    no event loop (subprocess and browser tests). Fails with the last value seen."""
    deadline = time.monotonic() + timeout_s
    last: T | None = None
    while time.monotonic() < deadline:
        last = check()
        if last:
            return last
        time.sleep(every_s)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}; last: {last!r}")


def holds_for_blocking(
    what: str, check: Callable[[], object], duration_s: float, every_s: float = 0.1
) -> None:
    """``holds_for`` for code with no event loop: ``check()`` stays true for
    ``duration_s``; fails the moment it is false."""
    end = time.monotonic() + duration_s
    while True:
        assert check(), f"{what} stopped holding"
        if time.monotonic() >= end:
            return
        time.sleep(min(every_s, max(0.0, end - time.monotonic())))


@contextlib.asynccontextmanager
async def loop_stalls() -> AsyncIterator[list[float]]:
    """How late this process's event loop wakes from 10 ms sleeps, again and again, while the
    block runs (the list fills as it goes). The longest is a time a busy machine did not run
    this process: a bound on how soon something in this process happens does not hold that
    against it."""
    lags_s: list[float] = []

    async def probe() -> None:
        loop = asyncio.get_running_loop()
        while True:
            due = loop.time() + 0.01
            await asyncio.sleep(0.01)
            lags_s.append(loop.time() - due)

    task = asyncio.get_running_loop().create_task(probe())
    try:
        yield lags_s
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
