"""STATUSTEXT reassembly (MAVLink 2 splits long texts into 50-byte chunks sharing an id)
and the recent texts that explain a refusal."""

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


# what stands in for a chunk that never arrived
MISSING_CHUNK = "…"


@dataclass
class _Pending:
    severity: int
    chunks: dict[int, str]
    started_s: float
    last_seq: int | None = None  # known once the short (NUL-terminated) chunk arrived


def clean_text(text: str) -> str:
    """PX4 ends its texts with a tab (and pads with NULs): neither is part of the text."""
    return text.rstrip("\0").rstrip()


class StatusTextAssembler:
    """Feeds chunks in, yields whole texts.

    MAVLink 2 splits a text longer than 50 bytes over STATUSTEXTs sharing a non-zero ``id``,
    numbered by ``chunk_seq``; a chunk shorter than 50 bytes ends its text, and a text in
    one chunk has id 0. Texts of different ids may interleave. A chunk lost in the middle
    shows as "…" once the last one arrives; a text whose last chunk got lost is released
    after ``timeout_s`` (``expire``), so a dropped frame costs part of a text, never all.
    """

    def __init__(self, clock: Callable[[], float], timeout_s: float = 1.0) -> None:
        self._clock = clock
        self.timeout_s = timeout_s
        self._pending: dict[int, _Pending] = {}

    @property
    def pending(self) -> bool:
        return bool(self._pending)

    def feed(self, severity: int, text: str, text_id: int, chunk_seq: int) -> list[tuple[int, str]]:
        """Return the texts completed by this chunk (and any timed out), as (severity, text)."""
        done = self.expire()
        if text_id == 0:
            done.append((severity, clean_text(text)))
            return done
        pending = self._pending.setdefault(text_id, _Pending(severity, {}, self._clock()))
        pending.chunks[chunk_seq] = text
        if len(text.encode("utf-8", "replace")) < STATUSTEXT_CHUNK_LEN:
            pending.last_seq = chunk_seq
        if pending.last_seq is not None:
            # chunks travel in order: one missing before the last is lost, not late
            done.append(self._release(text_id))
        return done

    def flush(self) -> list[tuple[int, str]]:
        return [self._release(i) for i in list(self._pending)]

    def expire(self) -> list[tuple[int, str]]:
        """Release the texts whose chunks stopped coming more than timeout_s ago."""
        now = self._clock()
        stale = [i for i, p in self._pending.items() if now - p.started_s > self.timeout_s]
        return [self._release(i) for i in stale]

    def _release(self, text_id: int) -> tuple[int, str]:
        pending = self._pending.pop(text_id)
        last = pending.last_seq if pending.last_seq is not None else max(pending.chunks)
        text = "".join(pending.chunks.get(seq, MISSING_CHUNK) for seq in range(last + 1))
        return pending.severity, clean_text(text)


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


# PX4's RTL announces its phases in STATUSTEXT ("RTL: climb to ...", "RTL: land at ...");
# the first keyword found names the phase, so the more specific ones come first.
_RTL_PHASES = (
    ("landed", "LANDED"),
    ("move to land", "MOVE_TO_LAND"),
    ("climb", "CLIMBING"),
    ("start return", "RETURNING"),
    ("return at", "RETURNING"),
    ("descend", "DESCENDING"),
    ("loiter", "LOITERING"),
    ("land", "LANDING"),
    ("completed", "COMPLETED"),
)


def rtl_phase_announced(text: str) -> str | None:
    """The RTL phase a PX4 text announces; None for a text that names none."""
    lowered = text.lower()
    if not lowered.startswith("rtl"):
        return None
    return next((phase for keyword, phase in _RTL_PHASES if keyword in lowered), None)
