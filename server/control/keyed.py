"""State kept per key (a token, a client address), made on first use and bounded: past the
limit, the key used least recently is forgotten first."""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, TypeVar

R = TypeVar("R")


class PerKey(Generic[R]):
    def __init__(self, make: Callable[[], R], max_keys: int) -> None:
        self._make = make
        self.max_keys = max_keys
        self._records: dict[str, R] = {}

    def get(self, key: str) -> R | None:
        """The key's state, if any, without counting as a use."""
        return self._records.get(key)

    def use(self, key: str) -> R:
        """The key's state (new if it had none), now the most recently used."""
        record = self._records.pop(key, None)
        if record is None:
            record = self._make()
        self._records[key] = record
        while len(self._records) > self.max_keys:
            del self._records[next(iter(self._records))]
        return record

    def forget(self, key: str) -> None:
        self._records.pop(key, None)
