"""The offboard setpoint streamer: one per vehicle, on absolute deadlines.

Ticks fall on t0 + k·period on the event loop's clock (loop.call_at), so a late tick does
not push every later one back; a tick that comes too late to matter is skipped and shows
up as a gap. A new setpoint goes out at once and re-phases the schedule.
"""

from __future__ import annotations

import asyncio
import math
from array import array
from collections.abc import Callable

from pymavlink.dialects.v20 import development as mavlink

from server.link.state import StreamStats

MIN_RATE_HZ = 2.0
MAX_RATE_HZ = 100.0
DEFAULT_RATE_HZ = 20.0
# An interval longer than this many periods counts as a gap.
GAP_PERIODS = 2.0


class SetpointStreamer:
    def __init__(
        self,
        send: Callable[[mavlink.MAVLink_message], None],
        *,
        rate_hz: float = DEFAULT_RATE_HZ,
        window: int = 1024,
    ) -> None:
        self._send = send
        self._period_s = 1.0 / self._checked_rate(rate_hz)
        self._msg: mavlink.MAVLink_message | None = None
        self._handle: asyncio.TimerHandle | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._t0 = 0.0
        self._k = 0
        self._started_s: float | None = None
        # statistics; the interval window is preallocated and overwritten in a ring
        self._intervals = array("d", bytes(8 * window))
        self._reset_stats()

    @staticmethod
    def _checked_rate(rate_hz: float) -> float:
        if not MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ:
            raise ValueError(f"stream rate must be {MIN_RATE_HZ:g}..{MAX_RATE_HZ:g} Hz")
        return rate_hz

    @property
    def rate_hz(self) -> float:
        return 1.0 / self._period_s

    @rate_hz.setter
    def rate_hz(self, rate_hz: float) -> None:
        self._period_s = 1.0 / self._checked_rate(rate_hz)
        if self.active:
            self._rephase()

    @property
    def active(self) -> bool:
        return self._handle is not None

    def stream(self, msg: mavlink.MAVLink_message) -> None:
        """Send ``msg`` now and then every period until stop() or the next stream()."""
        self._msg = msg
        self._loop = asyncio.get_running_loop()
        if self._started_s is None:
            # statistics describe the stream since it last started
            self._reset_stats()
            self._started_s = self._loop.time()
        self._emit(self._loop.time())
        self._rephase()

    def update(self, msg: mavlink.MAVLink_message) -> None:
        """Send ``msg`` from the next tick on without moving the schedule (a stream that
        must keep its rate whatever the rate of its updates); stream() it when stopped."""
        if not self.active:
            self.stream(msg)
            return
        self._msg = msg

    def _reset_stats(self) -> None:
        self._ring_next = 0
        self._ring_len = 0
        self._sent = 0
        self._gaps = 0
        self._max_interval_s = 0.0
        self._last_s: float | None = None
        # (sent count they were computed at, p50 s, p99 s): snapshots ask far more often
        # than intervals are added, and sorting the window is the costly part
        self._percentiles: tuple[int, float, float] | None = None

    def stop(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
        self._msg = None
        self._started_s = None

    def streaming_for_s(self) -> float:
        """How long the current stream has run without a stop (0 when stopped)."""
        if self._started_s is None or self._loop is None:
            return 0.0
        return self._loop.time() - self._started_s

    def _rephase(self) -> None:
        assert self._loop is not None
        if self._handle is not None:
            self._handle.cancel()
        self._t0 = self._last_s if self._last_s is not None else self._loop.time()
        self._k = 1
        self._handle = self._loop.call_at(self._t0 + self._period_s, self._tick)

    def _tick(self) -> None:
        assert self._loop is not None
        now = self._loop.time()
        self._emit(now)
        self._k += 1
        if self._t0 + self._k * self._period_s <= now:
            # late by more than a period: skip the missed ticks instead of bursting them
            self._k = math.floor((now - self._t0) / self._period_s) + 1
        self._handle = self._loop.call_at(self._t0 + self._k * self._period_s, self._tick)

    def _emit(self, now: float) -> None:
        if self._msg is None:
            return
        self._send(self._msg)
        if self._last_s is not None:
            interval = now - self._last_s
            self._intervals[self._ring_next] = interval
            self._ring_next = (self._ring_next + 1) % len(self._intervals)
            self._ring_len = min(self._ring_len + 1, len(self._intervals))
            if interval > GAP_PERIODS * self._period_s:
                self._gaps += 1
            self._max_interval_s = max(self._max_interval_s, interval)
        self._last_s = now
        self._sent += 1

    def stats(self) -> StreamStats:
        since_last_ms = None
        if self._last_s is not None:
            now = self._loop.time() if self._loop is not None else self._last_s
            since_last_ms = (now - self._last_s) * 1000.0
        if not self._ring_len:
            return StreamStats(active=self.active, sent=self._sent, since_last_ms=since_last_ms)
        # the rate over the last ~1 s, so it follows a rate change; percentiles use the window
        recent = self._recent(max(2, round(self.rate_hz)))
        if self._percentiles is None or self._percentiles[0] != self._sent:
            ordered = sorted(self._intervals[: self._ring_len])
            self._percentiles = (self._sent, _percentile(ordered, 0.50), _percentile(ordered, 0.99))
        _, p50_s, p99_s = self._percentiles
        return StreamStats(
            active=self.active,
            rate_hz=len(recent) / sum(recent) if sum(recent) > 0 else 0.0,
            interval_p50_ms=p50_s * 1000.0,
            interval_p99_ms=p99_s * 1000.0,
            max_gap_ms=self._max_interval_s * 1000.0,
            gaps=self._gaps,
            sent=self._sent,
            since_last_ms=since_last_ms,
        )

    def _recent(self, count: int) -> list[float]:
        """The last ``count`` recorded intervals (fewer if fewer were recorded)."""
        size = len(self._intervals)
        return [
            self._intervals[(self._ring_next - 1 - i) % size]
            for i in range(min(count, self._ring_len))
        ]


def _percentile(ordered: list[float], q: float) -> float:
    """Nearest-rank percentile of an ascending list."""
    rank = max(1, math.ceil(q * len(ordered)))
    return ordered[rank - 1]
