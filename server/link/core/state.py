"""Vehicle state snapshots (the classes generated from the wire models, in snapshot.py) and
latest-wins subscriptions to them."""

from __future__ import annotations

import asyncio
import math
import weakref
from collections import deque
from collections.abc import Callable
from typing import Literal

from server.link.codec.aio import loop_time_s

# the snapshot's classes, importable from here as from where they were once written
from server.link.codec.snapshot import *  # noqa: F403
from server.link.codec.snapshot import VehicleState

LandedState = Literal["UNDEFINED", "ON_GROUND", "IN_AIR", "TAKEOFF", "LANDING"]
VtolState = Literal["UNDEFINED", "MC", "FW", "TRANSITION_TO_FW", "TRANSITION_TO_MC"]

LANDED_STATE_NAMES: tuple[LandedState, ...] = (
    "UNDEFINED", "ON_GROUND", "IN_AIR", "TAKEOFF", "LANDING",
)  # fmt: skip
# EXTENDED_SYS_STATE.vtol_state: 0 undefined, 1 to FW, 2 to MC, 3 MC, 4 FW
VTOL_STATE_NAMES: tuple[VtolState, ...] = (
    "UNDEFINED", "TRANSITION_TO_FW", "TRANSITION_TO_MC", "MC", "FW",
)  # fmt: skip
# How long a rate-limited subscriber whose interval is up waits for a change newer than
# the one it missed: longer than the gaps between a vehicle's bursts of telemetry (50 ms
# for the simulated PX4), or it would often get the old change just before a new one.
LATE_CHANGE_WAIT_S = 0.2
# Readers woken per event-loop iteration: one vehicle update can make dozens of telemetry
# clients due at once, and their sends in one iteration would hold back the setpoint
# streamer's timer for milliseconds; in batches, timers run between them.
WAKE_BATCH = 8


class RateGrid:
    """At most one go per interval, on a grid: each go is allowed one interval after the
    previous one's slot, so the rate holds although each go comes a little after its slot;
    after a pause longer than an interval a new grid starts from now, never a burst."""

    def __init__(self, interval_s: float) -> None:
        self.interval_s = interval_s
        self.next_s = -math.inf  # the first go is due at once

    def due(self, now_s: float) -> bool:
        return now_s >= self.next_s

    def take(self, now_s: float) -> None:
        following_s = self.next_s + self.interval_s
        self.next_s = following_s if following_s > now_s else now_s + self.interval_s


class StateSubscription:
    """Async iterator of snapshots. Latest wins: however many changes happen between two
    reads, the reader gets one snapshot, built when it reads, so the backlog is one.

    With min_interval_s, reads come at most that often and each one is the first change
    after the interval is up, so the reader gets fresh state, not state that waited out the
    interval; a change held back that way is let through LATE_CHANGE_WAIT_S after the
    interval if no newer one has come by then. The reader sleeps until then (no timer wakes
    it early), which matters when hundreds of readers share the event loop."""

    def __init__(
        self,
        snapshot: Callable[[], VehicleState],
        on_close: Callable[[], None],
        min_interval_s: float = 0.0,
    ) -> None:
        self._snapshot = snapshot
        self._on_close = on_close
        self._changed = asyncio.Event()
        self._changed.set()  # a new subscriber gets the current state at once
        self._closed = False
        self._grid = RateGrid(min_interval_s)
        self._held_back: asyncio.TimerHandle | None = None
        self.queued = False  # due, waiting for its turn in the hub's wake batches

    @property
    def closed(self) -> bool:
        return self._closed

    def due(self, now_s: float) -> bool:
        """Told of a change at now_s (loop time): True if the reader should be woken
        for it now, False if it is held back (or the reader has not read the last one)."""
        if self._changed.is_set() or self.queued:
            return False
        if self._grid.interval_s > 0.0:
            if not self._grid.due(now_s):
                if self._held_back is None:
                    self._held_back = asyncio.get_running_loop().call_later(
                        self._grid.next_s + LATE_CHANGE_WAIT_S - now_s, self._let_through
                    )
                return False
            self._cancel_held_back()
        return True

    def wake(self) -> None:
        self.queued = False
        self._changed.set()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._cancel_held_back()
            self._on_close()
            self._changed.set()

    def __aiter__(self) -> StateSubscription:
        return self

    async def __anext__(self) -> VehicleState:
        if not await self.changed():
            raise StopAsyncIteration
        return self._snapshot()

    async def changed(self) -> bool:
        """Wait for a change since the last read, without building a snapshot (a reader
        that shares one encoding of the state needs only the signal); False once closed."""
        await self._changed.wait()
        if self._closed:
            return False
        self._changed.clear()
        if self._grid.interval_s > 0.0:
            self._grid.take(loop_time_s())
        return True

    def _let_through(self) -> None:
        self._held_back = None
        self._changed.set()

    def _cancel_held_back(self) -> None:
        if self._held_back is not None:
            self._held_back.cancel()
            self._held_back = None


class SubscriptionHub:
    """Holds subscriptions weakly so a consumer that forgets close() does not leak."""

    def __init__(self, snapshot: Callable[[], VehicleState]) -> None:
        self._snapshot = snapshot
        self._subs: weakref.WeakSet[StateSubscription] = weakref.WeakSet()
        # counts notifications, so a cache of anything derived from the state can tell
        # whether it is still current without subscribing
        self.version = 0
        self._to_wake: deque[StateSubscription] = deque()

    def subscribe(self, min_interval_s: float = 0.0) -> StateSubscription:
        holder: list[StateSubscription] = []
        sub = StateSubscription(
            self._snapshot, lambda: self._subs.discard(holder[0]), min_interval_s
        )
        holder.append(sub)
        self._subs.add(sub)
        return sub

    def notify(self) -> None:
        self.version += 1
        now_s = loop_time_s()
        batch_pending = bool(self._to_wake)  # then a _wake_batch is already scheduled
        for sub in list(self._subs):
            if sub.due(now_s):
                sub.queued = True
                self._to_wake.append(sub)
        if not batch_pending:
            self._wake_batch()

    def _wake_batch(self) -> None:
        for _ in range(min(WAKE_BATCH, len(self._to_wake))):
            self._to_wake.popleft().wake()
        if self._to_wake:
            asyncio.get_running_loop().call_soon(self._wake_batch)

    def close_all(self) -> None:
        for sub in list(self._subs):
            sub.close()
