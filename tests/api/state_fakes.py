"""Vehicles as the state publisher sees them, for tests and benchmarks: a snapshot from a
function, and move() telling subscribers of a change, as a link vehicle does; and the scene
hub fed by such vehicles the way the app feeds it."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from typing import cast

from server.control.publishers import StatePublishers
from server.link import Vehicle
from server.link.codec.aio import cancel_and_wait
from server.link.core.state import StateSubscription, SubscriptionHub, VehicleState
from server.scene.hub import SceneHub
from tests.scene.conftest import FakeVehicle


class PushingVehicle:
    def __init__(
        self, snapshot: Callable[[PushingVehicle], VehicleState], sysid: int = 1
    ) -> None:
        self.sysid = sysid
        self.connected = True
        self.moves = 0
        self._snapshot = snapshot
        self._hub = SubscriptionHub(self.snapshot)

    def snapshot(self) -> VehicleState:
        return self._snapshot(self)

    @property
    def state_version(self) -> int:
        return self._hub.version

    def subscribe(self, min_interval_s: float = 0.0) -> StateSubscription:
        return self._hub.subscribe(min_interval_s)

    def move(self) -> None:
        self.moves += 1
        self._hub.notify()


def pushing(fake: FakeVehicle) -> PushingVehicle:
    """A scene-test fake (a new state at every snapshot) that also tells of its changes."""
    return PushingVehicle(lambda _: fake.snapshot(), fake.sysid)


async def _change(vehicles: list[PushingVehicle], rate_hz: float) -> None:
    while True:
        for vehicle in vehicles:
            vehicle.move()
        await asyncio.sleep(1.0 / rate_hz)  # not a wait: the vehicles' telemetry rate


@contextlib.asynccontextmanager
async def scene_fed_by(
    hub: SceneHub, vehicles: list[PushingVehicle], change_rate_hz: float = 50.0
) -> AsyncIterator[StatePublishers]:
    """The scene hub started and fed as the app feeds it, through the state publishers,
    with every vehicle changing change_rate_hz times a second."""
    publishers = StatePublishers(
        lambda: cast("list[Vehicle]", vehicles), lambda _sysid: (None, None)
    )
    await publishers.start([])
    changing = asyncio.create_task(_change(vehicles, change_rate_hz))
    await hub.start(publishers)
    try:
        yield publishers
    finally:
        await hub.stop()
        await cancel_and_wait(changing)
        await publishers.close()
