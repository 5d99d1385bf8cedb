"""The wall clock the stepping loop paces itself by, injectable so tests control time.

Everything inside a simulated vehicle runs on sim time (the sum of its physics steps);
only the loop that decides *when* to step looks at a wall clock. `EventLoopClock` is the
real one (the running event loop's monotonic time, which the `looptime` pytest plugin
makes virtual); `ManualClock` moves only when a test advances it, so the loop's pacing,
speed-up and catch-up can be checked exactly and without waiting.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
from typing import Protocol

# Yields to the event loop before time moves, so a task started or woken runs up to its
# next await first (one is enough for the stepping loop; the rest is margin).
_YIELDS_PER_MOVE = 3


class Clock(Protocol):
    def now_s(self) -> float:
        """Seconds on a monotonic scale with an arbitrary zero."""
        ...

    async def sleep_until(self, deadline_s: float) -> None:
        """Return once now_s() has reached deadline_s (at once if it has already)."""
        ...


class EventLoopClock:
    """The running event loop's time (time.monotonic on Linux) and its timers."""

    def now_s(self) -> float:
        return asyncio.get_running_loop().time()

    async def sleep_until(self, deadline_s: float) -> None:
        await asyncio.sleep(max(deadline_s - self.now_s(), 0.0))


class ManualClock:
    """Virtual time that stands still until `advance()` or `stall()` moves it."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._now_s = start_s
        self._sleepers: list[tuple[float, int, asyncio.Future[None]]] = []
        self._order = itertools.count()

    def now_s(self) -> float:
        return self._now_s

    async def sleep_until(self, deadline_s: float) -> None:
        if deadline_s <= self._now_s:
            await asyncio.sleep(0)  # still a suspension point, as a real timer would be
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        heapq.heappush(self._sleepers, (deadline_s, next(self._order), future))
        await future

    async def advance(self, seconds: float) -> None:
        """Move time forward, waking each sleeper at its own deadline in order."""
        target_s = self._now_s + seconds
        await _let_others_run()
        while self._sleepers and self._sleepers[0][0] <= target_s:
            deadline_s, _, future = heapq.heappop(self._sleepers)
            self._now_s = max(self._now_s, deadline_s)
            if not future.done():
                future.set_result(None)
            await _let_others_run()
        self._now_s = target_s

    def stall(self, seconds: float) -> None:
        """Move time forward with nobody woken, as when the process was not scheduled."""
        self._now_s += seconds


async def _let_others_run() -> None:
    for _ in range(_YIELDS_PER_MOVE):
        await asyncio.sleep(0)
