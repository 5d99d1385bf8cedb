"""Backoff after wrong tokens, per client address: the first ``free_failures`` wrong tokens
cost nothing; each one after that locks the address out for twice as long as the last
(``base_s``, 2·base_s, … up to ``max_s``). While locked, every request from there that
carries a token is refused with its Retry-After, so guessing costs exponential time; a
right token afterwards clears the record. Other addresses are never affected."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from server.control.keyed import PerKey

# Addresses remembered at most; the least recently failed are forgotten first.
MAX_ADDRESSES = 10_000


@dataclass
class _Record:
    failures: int = 0
    locked_until_s: float = 0.0
    last_failure_s: float = 0.0


class Lockout:
    def __init__(
        self,
        free_failures: int = 10,
        base_s: float = 1.0,
        max_s: float = 300.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.free_failures = free_failures
        self.base_s = base_s
        self.max_s = max_s
        self._clock = clock
        self._records = PerKey(_Record, MAX_ADDRESSES)  # the least recently failed go first

    def retry_after_s(self, address: str) -> float:
        """0.0 when the address may try a token, else the seconds until it may."""
        record = self._records.get(address)
        if record is None:
            return 0.0
        now = self._clock()
        if record.locked_until_s > now:
            return record.locked_until_s - now
        if now - record.last_failure_s > 2 * self.max_s:
            self._records.forget(address)  # quiet for long enough: forgiven
        return 0.0

    def failed(self, address: str) -> float:
        """Count a wrong token; the lock it starts, in seconds (0.0 while still free)."""
        now = self._clock()
        record = self._records.use(address)
        record.failures += 1
        record.last_failure_s = now
        over = record.failures - self.free_failures
        lock_s = 0.0
        if over > 0:
            lock_s = min(self.max_s, self.base_s * 2.0 ** min(over - 1, 62))
            record.locked_until_s = now + lock_s
        return lock_s

    def succeeded(self, address: str) -> None:
        self._records.forget(address)

    def failures(self, address: str) -> int:
        record = self._records.get(address)
        return record.failures if record else 0
