"""The fleet view's feed from Zenoh: liveliness (with history, so edges already running are
seen at once), states of one tier, events, messages and stream health.

Zenoh calls back on its own threads: a sample is decoded there (JSON, off the loop) and
handed to the loop with call_soon_threadsafe; the view is only ever touched on the loop.
Malformed samples (a key outside the key space, a payload that is not a JSON object) are
counted and dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Callable
from typing import Any

import zenoh

from server.fleet.keys import FleetKeys, StateTier
from server.fleet.session import undeclare
from server.fleet.view import FleetView

log = logging.getLogger(__name__)


class FleetFeed:
    """Subscriptions of one session feeding one view."""

    def __init__(
        self, session: zenoh.Session, view: FleetView, tier: StateTier = "fast"
    ) -> None:
        self.session = session
        self.view = view
        self.keys = FleetKeys(view.fleet)
        self.tier: StateTier = tier
        self.dropped = 0  # malformed samples
        self._loop: asyncio.AbstractEventLoop | None = None
        self._subscribers: list[Any] = []

    def start(self) -> None:
        """Declare the subscribers (call on the loop: the loop is what they hand over to)."""
        self._loop = asyncio.get_running_loop()
        keys, view = self.keys, self.view
        self._subscribers = [
            self.session.declare_subscriber(
                keys.all_states(self.tier), self._handler(view.set_state)
            ),
            self.session.declare_subscriber(keys.all_of("events"), self._handler(view.add_event)),
            self.session.declare_subscriber(
                keys.all_of("messages"), self._handler(view.add_event)
            ),
            self.session.declare_subscriber(keys.all_of("stream"), self._handler(view.set_stream)),
        ]
        # last: a state that arrives first creates the vehicle as not alive until its token
        self._subscribers.append(
            self.session.liveliness().declare_subscriber(
                keys.all_alive(), zenoh.handlers.Callback(self._on_alive), history=True
            )
        )

    def stop(self) -> None:
        undeclare(*self._subscribers)
        self._subscribers = []

    # --- on Zenoh's threads -----------------------------------------------------------

    def _on_alive(self, sample: zenoh.Sample) -> None:
        try:
            edge, vehicle_id, rest = self.keys.parse(str(sample.key_expr))
        except ValueError:
            self._drop(sample)
            return
        if rest != "alive":
            self._drop(sample)
            return
        alive = sample.kind == zenoh.SampleKind.PUT
        self._to_loop(self.view.set_alive, edge, vehicle_id, alive)

    def _handler(
        self, apply: Callable[[str, int, dict[str, Any]], None]
    ) -> zenoh.handlers.Callback[zenoh.Sample]:
        def on_sample(sample: zenoh.Sample) -> None:
            try:
                edge, vehicle_id, _ = self.keys.parse(str(sample.key_expr))
                payload = json.loads(sample.payload.to_bytes())
            except ValueError:  # also JSONDecodeError and bad UTF-8
                self._drop(sample)
                return
            if vehicle_id is None or not isinstance(payload, dict):
                self._drop(sample)
                return
            self._to_loop(apply, edge, vehicle_id, payload)

        return zenoh.handlers.Callback(on_sample)

    def _to_loop(self, apply: Callable[..., None], *args: Any) -> None:
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile: shutting down
            loop.call_soon_threadsafe(apply, *args)

    def _drop(self, sample: zenoh.Sample) -> None:
        self.dropped += 1
        if self.dropped <= 10:
            log.warning("fleet: dropped a malformed sample on %s", sample.key_expr)
