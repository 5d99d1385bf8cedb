"""Latest-wins delivery, the slow-consumer policy of every state consumer in one place.

Every consumer of state or of a page-wide topic (a telemetry socket, the scene, the vehicle
list, scene clicks) reads through a slot of size one: a newer value replaces one not yet
read, so a consumer that falls behind gets the newest value, never a backlog, and a slow
consumer costs the server one reference, not a queue. The scene's per-vehicle watch
(publishers.FleetWatch) is the same rule with one slot per vehicle. What a telemetry socket
does with a send that stalls, and how events (which are not values and do queue) are
bounded, is in server/http/ws_common.py.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import Generic, TypeVar

T = TypeVar("T")

# Events are not values: each consumer's queue holds this many, the oldest dropped first
EVENT_BACKLOG = 256


class Slot(Generic[T]):
    """Latest wins: holds at most one value; put() replaces a value not yet read. Read it
    with `async for`, which ends once the slot is closed."""

    def __init__(self) -> None:
        self._value: T | None = None
        self._full = False
        self._ready = asyncio.Event()
        self.closed = False
        self.replaced = 0  # values overwritten before they were read

    def put(self, value: T) -> None:
        if self._full:
            self.replaced += 1
        self._value = value
        self._full = True
        self._ready.set()

    def close(self) -> None:
        self.closed = True
        self._ready.set()

    def __aiter__(self) -> AsyncIterator[T]:
        return self

    async def __anext__(self) -> T:
        await self._ready.wait()
        if self.closed or self._value is None:
            raise StopAsyncIteration
        value, self._value, self._full = self._value, None, False
        self._ready.clear()
        return value


class Broadcast:
    """One topic for every telemetry socket (the vehicle list, scene clicks), latest wins."""

    def __init__(self) -> None:
        self._slots: set[Slot[str]] = set()

    def subscribe(self, current: str | None = None) -> Slot[str]:
        slot: Slot[str] = Slot()
        if current is not None:
            slot.put(current)
        self._slots.add(slot)
        return slot

    def unsubscribe(self, slot: Slot[str]) -> None:
        self._slots.discard(slot)
        slot.close()

    def publish(self, text: str) -> None:
        for slot in self._slots:
            slot.put(text)
