"""A vehicle as the state publisher sees it, for tests and benchmarks: its snapshot comes
from a function, and move() tells its subscribers of a change, as a link vehicle does."""

from __future__ import annotations

from collections.abc import Callable

from server.link.state import StateSubscription, SubscriptionHub, VehicleState


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
