"""Rate limit per key: at most one accepted update per interval (latest state wins)."""

from __future__ import annotations

from collections.abc import Hashable

from server.link.state import RateGrid


class Throttle:
    """Accepts an update for a key when at least 1 / max_rate_hz has passed since the last,
    on a grid per key (RateGrid: no drift when called slightly late, no burst after a pause).

    Rejected updates are simply skipped: the caller always holds the newest state and
    offers it again on its next tick, so nothing queues up.
    """

    def __init__(self, max_rate_hz: float) -> None:
        if max_rate_hz <= 0.0:
            raise ValueError("max_rate_hz must be positive")
        self.min_interval_s = 1.0 / max_rate_hz
        self._grids: dict[Hashable, RateGrid] = {}

    def ready(self, key: Hashable, now_s: float) -> bool:
        grid = self._grids.get(key)
        if grid is None:
            grid = self._grids[key] = RateGrid(self.min_interval_s)
        if not grid.due(now_s):
            return False
        grid.take(now_s)
        return True

    def forget(self, key: Hashable) -> None:
        self._grids.pop(key, None)
