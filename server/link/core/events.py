"""Vehicle events (mode, armed, command, statustext, connection, ...) fanned out to
bounded queues. Policy: a slow consumer loses its oldest events, never blocks the link."""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field


@dataclass(frozen=True)
class VehicleEvent:
    kind: str
    time_s: float
    data: dict[str, object] = field(default_factory=dict)


class EventHub:
    """Fan-out of VehicleEvents; each subscriber queue drops its oldest entry when full."""

    def __init__(self) -> None:
        self._queues: list[asyncio.Queue[VehicleEvent]] = []

    def subscribe(self, maxsize: int = 256) -> asyncio.Queue[VehicleEvent]:
        queue: asyncio.Queue[VehicleEvent] = asyncio.Queue(maxsize=max(1, maxsize))
        self._queues.append(queue)
        return queue

    def unsubscribe(self, queue: asyncio.Queue[VehicleEvent]) -> None:
        if queue in self._queues:
            self._queues.remove(queue)

    def publish(self, kind: str, data: dict[str, object]) -> VehicleEvent:
        event = VehicleEvent(kind=kind, time_s=time.time(), data=data)
        for queue in self._queues:
            if queue.full():
                queue.get_nowait()
            queue.put_nowait(event)
        return event
