"""What a fleet server (``--fleet``) knows of the fleet: every edge and vehicle it has heard
of, who is alive (liveliness tokens), and each vehicle's latest state with when it arrived
and when its edge sent it.

Everything here runs on the event loop; view_zenoh.py hands Zenoh's samples over to it.
Presence is the liveliness tokens' alone: a vehicle is alive while its token is, and goes
lost the moment the token goes (its edge stopped, died, or was cut off and its Zenoh lease
ran out). A lost vehicle stays listed, with its last state, until it comes back.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from server.control.slots import EVENT_BACKLOG

# the state's fields a row of GET /fleet/vehicles shows
_SUMMARY_STATE_FIELDS = ("type", "mode", "armed", "connected", "global", "position_ned")


def vehicle_key(edge: str, vehicle_id: int) -> str:
    """A fleet vehicle's name: ``<edge>/<id>``."""
    return f"{edge}/{vehicle_id}"


@dataclass
class FleetVehicle:
    edge: str
    id: int
    alive: bool = False
    # the last state payload's "state" (GET /vehicles/{id} of its edge)
    state: dict[str, Any] | None = None
    seq: int | None = None
    sent_unix_s: float | None = None  # by the edge's clock, at publish
    received_s: float | None = None  # time.monotonic() when it arrived here
    stream: dict[str, Any] | None = None
    # bumped on every state and presence change: a socket sends what it has not sent
    version: int = 0
    _message: tuple[int, str] | None = field(default=None, repr=False)

    @property
    def key(self) -> str:
        return vehicle_key(self.edge, self.id)

    def age_s(self, now_s: float | None = None) -> float | None:
        """Since the last state arrived here."""
        if self.received_s is None:
            return None
        return max(0.0, (time.monotonic() if now_s is None else now_s) - self.received_s)

    def state_age_s(self, now_unix_s: float | None = None) -> float | None:
        """Since the edge published the last state (needs the clocks in step)."""
        if self.sent_unix_s is None:
            return None
        return (time.time() if now_unix_s is None else now_unix_s) - self.sent_unix_s

    def controller(self) -> str | None:
        lease = (self.state or {}).get("lease")
        if isinstance(lease, dict):
            holder = lease.get("holder")
            return holder if isinstance(holder, str) else None
        return None

    def fleet_fields(self) -> dict[str, Any]:
        """What the fleet knows of the vehicle besides its state: name, presence, ages."""
        return {
            "key": self.key,
            "edge": self.edge,
            "id": self.id,
            "alive": self.alive,
            "age_s": _rounded(self.age_s()),
            "state_age_s": _rounded(self.state_age_s()),
        }

    def summary(self) -> dict[str, Any]:
        """A row of GET /fleet/vehicles."""
        state = self.state or {}
        return {
            **self.fleet_fields(),
            "controller": self.controller(),
            **{name: state.get(name) for name in _SUMMARY_STATE_FIELDS},
        }

    def detail(self) -> dict[str, Any]:
        """GET /fleet/edges/{edge}/vehicles/{id}: the edge's state and the fleet's fields."""
        return {**(self.state or {}), **self.fleet_fields()}

    def state_message(self) -> str:
        """The fleet socket's `fleet_state` text, encoded once per version."""
        if self._message is None or self._message[0] != self.version:
            text = json.dumps(
                {
                    "type": "fleet_state",
                    "key": self.key,
                    "edge": self.edge,
                    "id": self.id,
                    "alive": self.alive,
                    "age_s": _rounded(self.age_s()),
                    "state": self.state,
                },
                allow_nan=False,
            )
            self._message = (self.version, text)
        return self._message[1]


@dataclass
class FleetEdge:
    name: str
    alive: bool = False
    vehicles: dict[int, FleetVehicle] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        return {"edge": self.name, "alive": self.alive, "vehicles": sorted(self.vehicles)}


class Watcher:
    """One fleet socket's feed: presence and events queued (oldest dropped when full);
    states are read latest-wins from the view at the socket's own rate."""

    def __init__(self, backlog: int = EVENT_BACKLOG) -> None:
        self.queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue(backlog)
        self.states_changed = asyncio.Event()
        self.states_changed.set()  # a new socket gets every state at once

    def put(self, message: dict[str, Any]) -> None:
        if self.queue.full():
            self.queue.get_nowait()
        self.queue.put_nowait(message)


class FleetView:
    """The fleet as this server last heard it; fed on the loop."""

    def __init__(self, fleet: str) -> None:
        self.fleet = fleet
        self.edges: dict[str, FleetEdge] = {}
        self._watchers: set[Watcher] = set()
        # called on the loop with each vehicle whose state or presence changed (the scene)
        self.on_change: list[Callable[[FleetVehicle], None]] = []

    # --- reading ----------------------------------------------------------------------

    def vehicles(self) -> list[FleetVehicle]:
        return [
            vehicle
            for edge in sorted(self.edges)
            for _, vehicle in sorted(self.edges[edge].vehicles.items())
        ]

    def vehicle(self, edge: str, vehicle_id: int) -> FleetVehicle | None:
        found = self.edges.get(edge)
        return None if found is None else found.vehicles.get(vehicle_id)

    def edge(self, name: str) -> FleetEdge | None:
        return self.edges.get(name)

    def summary(self) -> dict[str, Any]:
        return {
            "fleet": self.fleet,
            "edges": [self.edges[name].summary() for name in sorted(self.edges)],
        }

    # --- watching ---------------------------------------------------------------------

    def watch(self) -> Watcher:
        watcher = Watcher()
        self._watchers.add(watcher)
        return watcher

    def unwatch(self, watcher: Watcher) -> None:
        self._watchers.discard(watcher)

    def presence_messages(self) -> list[dict[str, Any]]:
        """Who is alive now, as a new socket first hears it."""
        messages = []
        for name in sorted(self.edges):
            edge = self.edges[name]
            messages.append(_presence(name, None, edge.alive))
            messages += [
                _presence(name, vid, vehicle.alive)
                for vid, vehicle in sorted(edge.vehicles.items())
            ]
        return messages

    # --- feeding (from view_zenoh.py, on the loop) ------------------------------------

    def _edge(self, name: str) -> FleetEdge:
        edge = self.edges.get(name)
        if edge is None:
            edge = self.edges[name] = FleetEdge(name)
        return edge

    def _vehicle(self, edge: str, vehicle_id: int) -> FleetVehicle:
        owner = self._edge(edge)
        vehicle = owner.vehicles.get(vehicle_id)
        if vehicle is None:
            vehicle = owner.vehicles[vehicle_id] = FleetVehicle(edge, vehicle_id)
        return vehicle

    def set_alive(self, edge: str, vehicle_id: int | None, alive: bool) -> None:
        """A liveliness token appeared (alive) or went (lost)."""
        if vehicle_id is None:
            owner = self._edge(edge)
            if owner.alive == alive:
                return
            owner.alive = alive
            self._broadcast(_presence(edge, None, alive))
            if not alive:
                # the edge's session is gone: so are its vehicles' tokens, whatever
                # order their deletions arrive in
                for vehicle in owner.vehicles.values():
                    self._vehicle_alive(vehicle, False)
        else:
            self._vehicle_alive(self._vehicle(edge, vehicle_id), alive)

    def _vehicle_alive(self, vehicle: FleetVehicle, alive: bool) -> None:
        if vehicle.alive == alive:
            return
        vehicle.alive = alive
        vehicle.version += 1
        self._broadcast(_presence(vehicle.edge, vehicle.id, alive))
        self._states_changed(vehicle)

    def set_state(self, edge: str, vehicle_id: int, payload: dict[str, Any]) -> None:
        """A state sample: ``{"edge", "id", "seq", "sent_unix_s", "state"}``."""
        state = payload.get("state")
        if not isinstance(state, dict):
            return
        # Zenoh delivers one publisher's samples in order; a restarted edge counts seq anew
        vehicle = self._vehicle(edge, vehicle_id)
        seq = payload.get("seq")
        vehicle.state = state
        vehicle.seq = seq if isinstance(seq, int) else None
        sent = payload.get("sent_unix_s")
        vehicle.sent_unix_s = float(sent) if isinstance(sent, int | float) else None
        vehicle.received_s = time.monotonic()
        vehicle.version += 1
        self._states_changed(vehicle)

    def set_stream(self, edge: str, vehicle_id: int, payload: dict[str, Any]) -> None:
        self._vehicle(edge, vehicle_id).stream = payload

    def add_event(self, edge: str, vehicle_id: int, payload: dict[str, Any]) -> None:
        """An event or message of a vehicle, as its edge's telemetry socket sends it."""
        self._vehicle(edge, vehicle_id)
        self._broadcast(
            {
                "type": "event",
                "key": vehicle_key(edge, vehicle_id),
                "edge": edge,
                "id": vehicle_id,
                "event": payload,
            }
        )

    def _broadcast(self, message: dict[str, Any]) -> None:
        for watcher in self._watchers:
            watcher.put(message)

    def _states_changed(self, vehicle: FleetVehicle) -> None:
        for watcher in self._watchers:
            watcher.states_changed.set()
        for callback in self.on_change:
            callback(vehicle)


def _presence(edge: str, vehicle_id: int | None, alive: bool) -> dict[str, Any]:
    return {
        "type": "presence",
        "key": edge if vehicle_id is None else vehicle_key(edge, vehicle_id),
        "edge": edge,
        "id": vehicle_id,
        "alive": alive,
    }


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(value, 3)
