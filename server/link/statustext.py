"""STATUSTEXT reassembly: MAVLink 2 splits long texts into 50-byte chunks sharing an id."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass

STATUSTEXT_CHUNK_LEN = 50
_MAV_SEVERITY_NAMES = (
    "EMERGENCY", "ALERT", "CRITICAL", "ERROR", "WARNING", "NOTICE", "INFO", "DEBUG",
)  # fmt: skip


def severity_name(severity: int) -> str:
    if 0 <= severity < len(_MAV_SEVERITY_NAMES):
        return _MAV_SEVERITY_NAMES[severity]
    return str(severity)


@dataclass
class _Pending:
    severity: int
    chunks: dict[int, str]
    started_s: float


class StatusTextAssembler:
    """Feeds chunks in, yields whole texts.

    A chunk shorter than 50 bytes ends its text (the sender NUL-terminates the last one).
    A text whose last chunk got lost is released after ``timeout_s`` or when another id
    starts, so a dropped frame costs at most a truncated text, never a lost one.
    """

    def __init__(self, clock: Callable[[], float], timeout_s: float = 1.0) -> None:
        self._clock = clock
        self._timeout_s = timeout_s
        self._pending: dict[int, _Pending] = {}

    def feed(self, severity: int, text: str, text_id: int, chunk_seq: int) -> list[tuple[int, str]]:
        """Return the texts completed by this chunk, as (severity, text)."""
        done = self._expire()
        if text_id == 0:
            done.append((severity, text))
            return done
        for other_id in [i for i in self._pending if i != text_id]:
            done.append(self._release(other_id))
        pending = self._pending.setdefault(text_id, _Pending(severity, {}, self._clock()))
        pending.chunks[chunk_seq] = text
        if len(text.encode("utf-8", "replace")) < STATUSTEXT_CHUNK_LEN:
            done.append(self._release(text_id))
        return done

    def flush(self) -> list[tuple[int, str]]:
        return [self._release(i) for i in list(self._pending)]

    def _expire(self) -> list[tuple[int, str]]:
        now = self._clock()
        stale = [i for i, p in self._pending.items() if now - p.started_s > self._timeout_s]
        return [self._release(i) for i in stale]

    def _release(self, text_id: int) -> tuple[int, str]:
        pending = self._pending.pop(text_id)
        text = "".join(pending.chunks[seq] for seq in sorted(pending.chunks))
        return pending.severity, text


MAV_SEVERITY_WARNING = 4


class RecentTexts:
    """The last texts with their arrival time, so a refusal can be explained by the
    STATUSTEXT that arrived around it."""

    def __init__(self, clock: Callable[[], float], keep: int = 20) -> None:
        self._clock = clock
        self._keep = keep
        self.items: list[tuple[float, int, str]] = []
        self._waiters: list[asyncio.Future[None]] = []

    def add(self, severity: int, text: str) -> None:
        self.items.append((self._clock(), severity, text))
        del self.items[: -self._keep]
        for waiter in self._waiters:
            if not waiter.done():
                waiter.set_result(None)
        self._waiters.clear()

    def latest_warning_since(self, since_s: float) -> str | None:
        """Newest text of severity WARNING or worse that arrived at or after since_s."""
        for time_s, severity, text in reversed(self.items):
            if time_s < since_s:
                break
            if severity <= MAV_SEVERITY_WARNING:
                return text
        return None

    async def wait_warning_since(self, since_s: float, timeout_s: float) -> str | None:
        """latest_warning_since, waiting up to timeout_s for one to arrive."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while (text := self.latest_warning_since(since_s)) is None:
            remaining = deadline - loop.time()
            if remaining <= 0:
                return None
            waiter: asyncio.Future[None] = loop.create_future()
            self._waiters.append(waiter)
            try:
                await asyncio.wait_for(waiter, remaining)
            except TimeoutError:
                return None
        return text
