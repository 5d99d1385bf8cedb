"""Token buckets: a rate with a burst, per key (a token's role); what a refused call waits.

A bucket holds up to ``burst`` calls and refills at ``rate_per_s``; each call takes one. A
refused call is told how long until the next one would pass (the Retry-After)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from server.control.keyed import PerKey

Clock = Callable[[], float]
# Keys with a bucket at the most; a forgotten key starts again with a full burst.
MAX_KEYS = 10_000
_EPSILON = 1e-9


@dataclass
class TokenBucket:
    rate_per_s: float
    burst: float
    clock: Clock = time.monotonic
    _level: float = field(init=False)
    _at_s: float = field(init=False)

    def __post_init__(self) -> None:
        self._level = self.burst
        self._at_s = self.clock()

    def take(self) -> float:
        """Take one call: 0.0 when it passes, else the seconds until one would."""
        now = self.clock()
        self._level = min(self.burst, self._level + (now - self._at_s) * self.rate_per_s)
        self._at_s = now
        if self._level >= 1.0 - _EPSILON:  # a refill's rounding must not refuse a call
            self._level = max(0.0, self._level - 1.0)
            return 0.0
        return (1.0 - self._level) / self.rate_per_s


class RateLimiter:
    """One bucket per key, all with the same rate and burst."""

    def __init__(self, rate_per_s: float, burst: float, clock: Clock = time.monotonic) -> None:
        self.rate_per_s = rate_per_s
        self.burst = burst
        self._buckets = PerKey(lambda: TokenBucket(rate_per_s, burst, clock), MAX_KEYS)

    def take(self, key: str) -> float:
        return self._buckets.use(key).take()
