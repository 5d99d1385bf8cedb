"""What an edge publishes of one vehicle (docs/fleet.md, "Edge"): its liveliness token while
its link is connected, its state at two rate tiers, its events, its messages and, while a
setpoint stream runs, the stream's health.

State comes from the vehicle's one state publisher (server/control/publisher.py), as a
consumer at each tier's rate: the tick's JSON is the one the telemetry sockets send (made
once per tick, whoever reads it), wrapped as
``{"edge", "id", "seq", "sent_unix_s", "state": <GET /api/v1/vehicles/{id}>}``.

``seq`` orders a vehicle's samples across both tiers: one number per tick (a tick sent on
both tiers carries the same one), never going back (a tier that would send an older tick
than the other already sent sends the newer one). It starts at the edge's start time in
milliseconds, so it keeps growing across restarts of the edge (a fleet server that drops
samples older than the last one it has does not drop a restarted edge's).

Puts run on the event loop; they never block (Zenoh drops a sample rather than wait when
the network is congested), and nothing the setpoint stream depends on goes through here.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from typing import Any

import zenoh

from server.control.publisher import Published, StatePublisher
from server.control.slots import EVENT_BACKLOG
from server.control.views import event_message, state_json, stream_dict
from server.fleet.keys import TIER_RATE_HZ, FleetKeys, StateTier
from server.fleet.session import undeclare
from server.link import Vehicle
from server.link.codec.aio import cancel_and_wait

log = logging.getLogger(__name__)

# event kinds that go to .../messages (texts for a person); every other kind to .../events
MESSAGE_KINDS = frozenset({"statustext", "px4_event"})
STREAM_PERIOD_S = 1.0
_JSON = zenoh.Encoding.APPLICATION_JSON
_EVENTS = zenoh.Priority.DATA_HIGH


def _dumps(value: Any) -> bytes:
    return json.dumps(value, separators=(",", ":"), allow_nan=False).encode()


def _declare(
    session: zenoh.Session, key: str, priority: zenoh.Priority = zenoh.Priority.DATA
) -> zenoh.Publisher:
    # DROP: a put on the loop never waits for a congested link (Zenoh's default, said here)
    return session.declare_publisher(
        key, encoding=_JSON, congestion_control=zenoh.CongestionControl.DROP, priority=priority
    )


class Sequence:
    """One vehicle's sample numbers: one per tick, in tick order, across tiers."""

    def __init__(self, start: int) -> None:
        self.seq = start
        self.newest: Published | None = None

    def stamp(self, published: Published) -> tuple[int, Published]:
        """(seq, the tick to send): the newest tick seen if ``published`` is older."""
        newest = self.newest
        # a tick re-taken for a read (same version, later) is newer too: the age in it grew
        if newest is None or (published.version, published.taken_s) > (
            newest.version, newest.taken_s
        ):
            self.seq += 1
            self.newest = published
            return self.seq, published
        return self.seq, newest


class VehiclePublication:
    """The keys of one vehicle of this edge, and the tasks that feed them."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: FleetKeys,
        edge: str,
        vehicle: Vehicle,
        publisher: StatePublisher,
        seq_start: int,
    ) -> None:
        self.session = session
        self.vehicle = vehicle
        self.publisher = publisher
        self.vehicle_id = vehicle.sysid
        self._alive_key = keys.vehicle_alive(edge, self.vehicle_id)
        self._head = f'{{"edge":{json.dumps(edge)},"id":{self.vehicle_id},"seq":'.encode()
        self._extra = {"edge": edge, "id": self.vehicle_id}
        self._sequence = Sequence(seq_start)
        self._state = {
            tier: _declare(session, keys.state(edge, self.vehicle_id, tier))
            for tier in TIER_RATE_HZ
        }
        # events are rare and each one counts: a queue of their own, ahead of the states
        self._events = _declare(session, keys.events(edge, self.vehicle_id), _EVENTS)
        self._messages = _declare(session, keys.messages(edge, self.vehicle_id), _EVENTS)
        self._stream = _declare(session, keys.stream(edge, self.vehicle_id))
        self._token: zenoh.LivelinessToken | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self.sent: dict[str, int] = {"fast": 0, "slow": 0, "events": 0, "messages": 0, "stream": 0}

    def start(self) -> None:
        name = f"edge-{self.vehicle_id}"
        for tier in TIER_RATE_HZ:
            self._tasks.append(asyncio.create_task(self._pump_state(tier), name=f"{name}-{tier}"))
        self._tasks.append(asyncio.create_task(self._pump_events(), name=f"{name}-events"))
        self._tasks.append(asyncio.create_task(self._pump_stream(), name=f"{name}-stream"))
        self.sync_alive()

    def sync_alive(self) -> None:
        """The vehicle's liveliness token exists exactly while its link is connected."""
        connected = self.vehicle.connected
        if connected and self._token is None:
            self._token = self.session.liveliness().declare_token(self._alive_key)
        elif not connected and self._token is not None:
            token, self._token = self._token, None
            undeclare(token)

    @property
    def last_seq(self) -> int:
        return self._sequence.seq

    @property
    def alive(self) -> bool:
        return self._token is not None

    async def close(self) -> None:
        for task in self._tasks:
            await cancel_and_wait(task)
        self._tasks.clear()
        token, self._token = self._token, None
        undeclare(*self._state.values(), self._events, self._messages, self._stream, token)

    def state_sample(self, published: Published) -> bytes:
        """The tier's sample of a tick: the REST body of the vehicle, wrapped."""
        seq, published = self._sequence.stamp(published)
        state = state_json(published.state, published.body, published.lease)
        return b"%s%d,\"sent_unix_s\":%r,\"state\":%s}" % (self._head, seq, time.time(), state)

    async def _pump_state(self, tier: StateTier) -> None:
        slot = self.publisher.subscribe(TIER_RATE_HZ[tier])
        publisher = self._state[tier]
        try:
            async for published in slot:
                publisher.put(self.state_sample(published))
                self.sent[tier] += 1
        finally:
            self.publisher.unsubscribe(slot)

    async def _pump_events(self) -> None:
        queue = self.vehicle.subscribe_events(EVENT_BACKLOG)
        try:
            while True:
                event = await queue.get()
                message = {**event_message(self.vehicle_id, event), **self._extra}
                leaf = "messages" if event.kind in MESSAGE_KINDS else "events"
                target = self._messages if leaf == "messages" else self._events
                target.put(_dumps(message))
                self.sent[leaf] += 1
        finally:
            self.vehicle.unsubscribe_events(queue)

    async def _pump_stream(self) -> None:
        """The stream's figures each second while it runs, and once when it stops."""
        was_active = False
        while True:
            await asyncio.sleep(STREAM_PERIOD_S)
            stats = self.vehicle.stream_stats()
            if stats.active or was_active:
                self._stream.put(_dumps({**stream_dict(stats), **self._extra}))
                self.sent["stream"] += 1
            was_active = stats.active
