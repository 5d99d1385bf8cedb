"""Every vehicle's state publisher (publisher.py), made when the vehicle is discovered or
first asked for, and the page-wide topics: the vehicle list, clicks in the 3D scene, and
every vehicle's newest state for the scene (`FleetWatch`, one latest-wins slot per vehicle)."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable, Iterable

from server.control.publisher import DEFAULT_MAX_RATE_HZ, Published, StatePublisher
from server.control.slots import Broadcast
from server.control.views import LeaseStatus, summary_dict
from server.link import Link, Vehicle, VehicleState


class FleetWatch:
    """Every vehicle's newest state at one rate (the scene): one slot per vehicle."""

    def __init__(self, on_close: Callable[[FleetWatch], None]) -> None:
        self._on_close = on_close
        self._pending: dict[int, VehicleState] = {}
        self._ready = asyncio.Event()

    def put(self, published: Published) -> None:
        self._pending[published.state.sysid] = published.state
        self._ready.set()

    async def next_states(self) -> list[VehicleState]:
        """The newest state of each vehicle that changed since the last call."""
        await self._ready.wait()
        self._ready.clear()
        states = list(self._pending.values())
        self._pending.clear()
        return states

    def close(self) -> None:
        self._on_close(self)


class StatePublishers:
    """The publishers of every vehicle, made when a vehicle is discovered or first asked
    for, and the page-wide topics: the vehicle list and clicks in the 3D scene."""

    def __init__(
        self,
        vehicles: Callable[[], list[Vehicle]],
        lease_status: Callable[[int], LeaseStatus],
        *,
        max_rate_hz: float = DEFAULT_MAX_RATE_HZ,
    ) -> None:
        self._vehicles = vehicles
        self._lease_status = lease_status
        self.max_rate_hz = max_rate_hz
        self._publishers: dict[int, StatePublisher] = {}
        self._watches: dict[FleetWatch, float] = {}
        self._tasks: list[asyncio.Task[None]] = []
        self.vehicle_list = Broadcast()
        self.scene_clicks = Broadcast()

    async def start(self, links: Iterable[Link]) -> None:
        for link in links:
            self._tasks.append(asyncio.create_task(self._discover(link)))
        self._refresh()

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks.clear()
        for publisher in list(self._publishers.values()):
            await publisher.close()
        self._publishers.clear()

    def for_vehicle(self, vehicle: Vehicle) -> StatePublisher:
        publisher = self._publishers.get(vehicle.sysid)
        if publisher is None or publisher.vehicle is not vehicle:
            publisher = StatePublisher(
                vehicle,
                self._lease_status,
                max_rate_hz=self.max_rate_hz,
                on_listing_change=self._publish_vehicle_list,
            )
            self._publishers[vehicle.sysid] = publisher
            publisher.start()
            for watch, rate_hz in self._watches.items():
                publisher.add(watch, rate_hz)
        return publisher

    def watch_states(self, rate_hz: float) -> FleetWatch:
        """Every vehicle's state, now and discovered later, at most rate_hz each."""
        watch = FleetWatch(self._unwatch)
        self._watches[watch] = rate_hz
        for publisher in self._publishers.values():
            publisher.add(watch, rate_hz)
        return watch

    def vehicle_list_message(self) -> str:
        summaries = [summary_dict(vehicle.snapshot()) for vehicle in self._vehicles()]
        return json.dumps({"type": "vehicles", "vehicles": summaries}, separators=(",", ":"))

    def publish_click(self, click: dict[str, object]) -> None:
        self.scene_clicks.publish(
            json.dumps({"type": "scene_click", **click}, separators=(",", ":"))
        )

    def _unwatch(self, watch: FleetWatch) -> None:
        self._watches.pop(watch, None)
        for publisher in self._publishers.values():
            publisher.remove(watch)

    async def _discover(self, link: Link) -> None:
        queue = link.subscribe_vehicles()
        try:
            while True:
                await queue.get()
                self._refresh()
                self._publish_vehicle_list()
        finally:
            link.unsubscribe_vehicles(queue)

    def _refresh(self) -> None:
        for vehicle in self._vehicles():
            self.for_vehicle(vehicle)

    def _publish_vehicle_list(self) -> None:
        self.vehicle_list.publish(self.vehicle_list_message())
