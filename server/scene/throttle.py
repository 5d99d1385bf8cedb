"""Rate limit per key: at most one accepted update per interval (latest state wins)."""

from __future__ import annotations

from collections.abc import Hashable


class Throttle:
    """Accepts an update for a key when at least 1 / max_rate_hz has passed since the last.

    Rejected updates are simply skipped: the caller always holds the newest state and
    offers it again on its next tick, so nothing queues up.
    """

    def __init__(self, max_rate_hz: float) -> None:
        if max_rate_hz <= 0.0:
            raise ValueError("max_rate_hz must be positive")
        self.min_interval_s = 1.0 / max_rate_hz
        self._last_s: dict[Hashable, float] = {}

    def ready(self, key: Hashable, now_s: float) -> bool:
        last = self._last_s.get(key)
        if last is not None and now_s - last < self.min_interval_s:
            return False
        # Keep the cadence on the ideal grid when called slightly late, but never let
        # a long pause produce a burst afterwards.
        if last is not None and now_s - last < 2.0 * self.min_interval_s:
            self._last_s[key] = last + self.min_interval_s
        else:
            self._last_s[key] = now_s
        return True

    def forget(self, key: Hashable) -> None:
        self._last_s.pop(key, None)
