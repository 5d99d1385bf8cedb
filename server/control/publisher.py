"""One state publisher per vehicle: a snapshot taken once per tick, encoded once, fanned out
at rate tiers to every telemetry socket, REST read and the scene.

Data path: the publisher sleeps until the next slot of a rate tier, then takes one
snapshot (a tick, a `Published`) just after the vehicle's next message, and hands that same
object to the consumers of every tier due. No tier due, no snapshot and no wake-up per
message: a vehicle whose telemetry changes 50 times a second but is watched at 4 Hz costs 4
snapshots a second, which matters with 50 vehicles on one server. Its JSON is made on
first use and kept on the object, so a tick is encoded at most once however many sockets
send it, and not at all when only the scene (which wants the snapshot itself) is watching.

Slow consumers: every consumer reads through a latest-wins slot (slots.py, where the policy
is written down): a `Slot`, or the scene's `FleetWatch`, one slot per vehicle.

Rate tiers: consumers that ask for the same rate share one tier, one RateGrid. When a
tier's slot comes the publisher waits for the vehicle's next message (at most 90 % of the
tier's interval; the grid keeps the rate however late within it a delivery is) and takes
the tick right after it: a snapshot taken at an earlier change would add its age to every
client's latency. With nothing new in that time it sends what changed since the last tick,
and nothing at all when nothing changed.

The tick's encoded state, for consumers that are not telemetry sockets (a fleet edge): a
`Slot[Published]` from subscribe(rate_hz) yields ticks; `Published.version` orders them
and `Published.body` is the state JSON (bytes, without `type`, `id`, `lease`), made once
per tick and shared with every socket; `Published.message` the telemetry socket's text.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

from server.control.slots import Slot
from server.control.views import (
    LeaseStatus,
    encode_state,
    encode_steady_state,
    state_json,
    state_message,
)
from server.link import VehicleState
from server.link.codec.aio import cancel_and_wait, loop_time_s
from server.link.core.state import WAKE_BATCH, RateGrid, StateSubscription

DEFAULT_MAX_RATE_HZ = 50.0
# How often the vehicle's connection is checked (for the vehicle list) when no tier is due
# sooner: the publisher sleeps between deliveries instead of waking at every message.
LISTING_CHECK_S = 0.25
# A timer may fire a little before its time (the loop's clock resolution, a virtual clock's
# rounding): a tier this close to its slot counts as due.
DUE_SLACK_S = 0.001
# A due tier waits this share of its interval for the vehicle's next message: a tick taken
# at an older one would add that message's age (up to a telemetry period) to every client.
NEXT_MESSAGE_WAIT_SHARE = 0.9


class PublishedVehicle(Protocol):
    """What a publisher reads of a vehicle."""

    sysid: int

    @property
    def connected(self) -> bool: ...
    @property
    def state_version(self) -> int: ...
    def snapshot(self) -> VehicleState: ...
    def subscribe(self, min_interval_s: float = 0.0) -> StateSubscription: ...


@dataclass(eq=False)
class Published:
    """One tick: the snapshot, the lease at that moment, and the encodings, each made once
    on first use and then shared by every consumer of the tick."""

    state: VehicleState
    version: int
    lease: LeaseStatus
    taken_s: float
    encode: Callable[[VehicleState], bytes]

    @cached_property
    def body(self) -> bytes:
        return self.encode(self.state)

    @cached_property
    def steady(self) -> tuple[str | None, bytes]:
        """What the tick tells apart from the time passing (views.encode_steady_state) and
        who holds the lease: equal for two ticks of a vehicle where nothing else changed."""
        return self.lease[0], encode_steady_state(self.state)

    @cached_property
    def message(self) -> str:
        """The telemetry socket's `{type: "state"}` text."""
        return state_message(self.state, self.body, self.lease)


class Sink(Protocol):
    def put(self, published: Published) -> None: ...


class _Tier:
    """Consumers that asked for the same rate: one grid, one delivery decision for all."""

    def __init__(self, interval_s: float) -> None:
        self.grid = RateGrid(interval_s)
        self.sinks: set[Sink] = set()
        self.sent: Published | None = None


class StatePublisher:
    """The state of one vehicle, for every consumer: subscribe(rate_hz) for a latest-wins
    slot of ticks at that rate (capped at max_rate_hz), latest() / rest_json() for reads."""

    def __init__(
        self,
        vehicle: PublishedVehicle,
        lease_status: Callable[[int], LeaseStatus],
        *,
        max_rate_hz: float = DEFAULT_MAX_RATE_HZ,
        encode: Callable[[VehicleState], bytes] = encode_state,
        on_listing_change: Callable[[], None] | None = None,
    ) -> None:
        self.vehicle = vehicle
        self.max_rate_hz = max_rate_hz
        self.current: Published | None = None
        self.encodes = 0  # JSON encodings made: at most one per tick
        self.ticks = 0
        self._lease_status = lease_status
        self._encode_state = encode
        self._on_listing_change = on_listing_change
        self._listing = vehicle.connected
        self._tiers: dict[float, _Tier] = {}
        self._tier_of: dict[Sink, _Tier] = {}
        self._to_put: deque[tuple[Sink, Published]] = deque()
        self._rescheduled = asyncio.Event()
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        if self._task is None:
            self._task = asyncio.create_task(self._run(), name=f"state-{self.vehicle.sysid}")

    async def close(self) -> None:
        await cancel_and_wait(self._task)
        self._task = None
        self._close_sinks()

    def subscribe(self, rate_hz: float) -> Slot[Published]:
        slot: Slot[Published] = Slot()
        self.add(slot, rate_hz)
        return slot

    def add(self, sink: Sink, rate_hz: float) -> None:
        """Deliver ticks to sink at most rate_hz (and the current state at once)."""
        self.remove(sink)
        interval_s = round(1.0 / min(rate_hz, self.max_rate_hz), 6)
        published = self.latest()
        tier = self._tiers.get(interval_s)
        if tier is None:
            tier = self._tiers[interval_s] = _Tier(interval_s)
            tier.sent = published
            tier.grid.take(loop_time_s())
            self._rescheduled.set()
        tier.sinks.add(sink)
        self._tier_of[sink] = tier
        sink.put(published)

    def remove(self, sink: Sink) -> None:
        tier = self._tier_of.pop(sink, None)
        if tier is None:
            return
        tier.sinks.discard(sink)
        if not tier.sinks:
            del self._tiers[tier.grid.interval_s]

    def unsubscribe(self, slot: Slot[Published]) -> None:
        self.remove(slot)
        slot.close()

    @property
    def consumers(self) -> int:
        return len(self._tier_of)

    def latest(self, max_age_s: float | None = None) -> Published:
        """The current tick, or a new one if the state changed since (or, with max_age_s,
        if the tick is older than that: the heartbeat age in it grows with time)."""
        current = self.current
        if (
            current is None
            or current.version != self.vehicle.state_version
            or (max_age_s is not None and loop_time_s() - current.taken_s > max_age_s)
        ):
            current = self._take()
        return current

    def rest_json(self) -> bytes:
        """GET /vehicles/{id}: the latest encoding, with the lease as it is now."""
        published = self.latest(max_age_s=1.0 / self.max_rate_hz)
        lease = self._lease_status(published.state.sysid)
        return state_json(published.state, published.body, lease)

    def fan_out(self, published: Published, sinks: Iterable[Sink]) -> None:
        """Hand one tick to sinks, WAKE_BATCH per event-loop iteration: a tick can make
        dozens of sockets due at once, and their sends in one iteration would hold back the
        setpoint streamer's timer for milliseconds; in batches, timers run between them."""
        batch_pending = bool(self._to_put)
        self._to_put.extend((sink, published) for sink in sinks)
        if not batch_pending:
            self._put_batch()

    def _put_batch(self) -> None:
        for _ in range(min(WAKE_BATCH, len(self._to_put))):
            sink, published = self._to_put.popleft()
            sink.put(published)
        if self._to_put:
            asyncio.get_running_loop().call_soon(self._put_batch)

    def _take(self) -> Published:
        self.ticks += 1
        state = self.vehicle.snapshot()
        self.current = Published(
            state,
            self.vehicle.state_version,
            self._lease_status(state.sysid),
            loop_time_s(),
            self._encode,
        )
        return self.current

    def _encode(self, state: VehicleState) -> bytes:
        self.encodes += 1
        return self._encode_state(state)

    async def _run(self) -> None:
        # min_interval 0: woken by the first change after each read, at once. The
        # publisher reads only while a tier is due, so between deliveries the vehicle's
        # messages cost it nothing (the hub sees the signal is already set).
        subscription = self.vehicle.subscribe()
        try:
            while not subscription.closed:
                self._check_listing()
                now_s = loop_time_s() + DUE_SLACK_S
                due_s = min((tier.grid.next_s for tier in self._tiers.values()), default=None)
                if due_s is None or due_s > now_s:
                    wake_s = now_s + LISTING_CHECK_S
                    await self._sleep_until(wake_s if due_s is None else min(due_s, wake_s))
                    continue
                fastest_s = min(
                    t.grid.interval_s for t in self._tiers.values() if t.grid.due(now_s)
                )
                if not await self._next_change(subscription, fastest_s * NEXT_MESSAGE_WAIT_SHARE):
                    break
                self._deliver_due(loop_time_s() + DUE_SLACK_S)
        finally:
            subscription.close()
            self._close_sinks()

    async def _sleep_until(self, when_s: float) -> None:
        """Until when_s (loop time), or until a consumer is added with a sooner rate."""
        self._rescheduled.clear()
        try:
            async with asyncio.timeout_at(when_s):
                await self._rescheduled.wait()
        except TimeoutError:
            pass

    async def _next_change(self, subscription: StateSubscription, wait_s: float) -> bool:
        """A tier is due: wait for the vehicle's next message, so the tick is taken just
        after it (its age adds nothing to the clients' latency); if none comes within
        wait_s (most of the tier's interval: the grid keeps the rate however late a delivery
        is within it, and PX4's 20 Hz telemetry gives a 10 Hz tier a message within it),
        go with what changed since the last tick. False once closed."""
        version = self.vehicle.state_version
        current = self.current
        nothing_new = current is not None and current.version == version
        try:
            async with asyncio.timeout(LISTING_CHECK_S if nothing_new else wait_s):
                while self.vehicle.state_version == version:
                    if not await subscription.changed():
                        return False
        except TimeoutError:
            pass
        return True

    def _deliver_due(self, now_s: float) -> None:
        for tier in list(self._tiers.values()):
            if not tier.grid.due(now_s):
                continue
            published = self.latest()
            if published is tier.sent:
                continue  # nothing new: the tier stays due and takes the next change
            tier.sent = published
            tier.grid.take(now_s)
            self.fan_out(published, tier.sinks)

    def _check_listing(self) -> None:
        if self.vehicle.connected != self._listing:
            self._listing = self.vehicle.connected
            if self._on_listing_change is not None:
                self._on_listing_change()

    def _close_sinks(self) -> None:
        for sink in list(self._tier_of):
            self.remove(sink)
            if isinstance(sink, Slot):
                sink.close()

