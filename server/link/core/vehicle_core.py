"""What every vehicle plugin shares: who the vehicle is, whether it is heard, how to send
to it, the one request protocol, its events and its state notifications.

The core knows nothing of the Link: it is given a ``Sender`` (the Link is one), and it
routes each message the Link hands it to the handlers the plugins registered.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, Protocol

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.statustext import RecentTexts
from server.link.core.events import EventHub
from server.link.core.link_stats import LinkStats
from server.link.core.liveness import LinkQuality
from server.link.core.requests import Requester
from server.link.core.state import SubscriptionHub, VehicleState
from server.link.stream.stream_channel import StreamChannel

MessageHandler = Callable[[Any], None]


class Sender(Protocol):
    """What a vehicle needs of its connection: a codec with the GCS's own ids, a way to
    send, and the connection's statistics."""

    mav: mavlink.MAVLink

    def send(self, msg: mavlink.MAVLink_message) -> None: ...

    def stats(self) -> LinkStats: ...


class VehicleCore:
    """Identity, HEARTBEAT and connection state, the send path and the requester."""

    def __init__(
        self,
        *,
        sender: Sender,
        sysid: int,
        compid: int,
        heartbeat: mavlink.MAVLink_heartbeat_message | None,
        snapshot: Callable[[], VehicleState],
    ) -> None:
        # taken once: snapshot() may be called from other threads (the scene), and the
        # loop's clock is the one a test can make virtual
        self._loop = asyncio.get_running_loop()
        self.sender = sender
        self.sysid = sysid
        self.compid = compid
        self.mav_type = heartbeat.type if heartbeat is not None else 0
        self.autopilot = heartbeat.autopilot if heartbeat is not None else 0
        self.connected = True
        self.lost_s: float | None = None  # when the link last lost the vehicle
        self.lost_reason: str | None = None  # how it noticed, while the vehicle is lost
        self.link_quality: LinkQuality | None = None  # the link's figures, 10 times a second
        self.created_s = self.last_heartbeat_s = self.updated_s = self.now()
        self.events = EventHub()
        self.hub = SubscriptionHub(snapshot)
        self.texts = RecentTexts(self.now)
        self.requests = Requester(
            send=sender.send, mav=sender.mav, target=(sysid, compid), texts=self.texts,
            publish=self.publish_event,
            input_pending=getattr(sender, "input_pending", lambda: False),
        )  # fmt: skip
        self._handlers: dict[str, list[MessageHandler]] = {
            "HEARTBEAT": [self._on_heartbeat],
            "COMMAND_ACK": [lambda ack: self.requests.handle_ack(ack, ack.get_srcComponent())],
        }
        self._on_connection: list[Callable[[bool], None]] = []

    def now(self) -> float:
        """Seconds on the event loop's clock."""
        return self._loop.time()

    @property
    def mav(self) -> mavlink.MAVLink:
        return self.sender.mav

    def send(self, msg: mavlink.MAVLink_message) -> None:
        self.sender.send(msg)

    def stream_channel(self, on_ticks: Callable[[int, list[float]], None]
                       ) -> StreamChannel | None:
        """A stream in the link's sender process, where the link has one."""
        factory = getattr(self.sender, "stream_channel", None)
        return factory(on_ticks) if factory is not None else None

    # -- wiring (plugins register at construction) ---------------------------------------
    def on_message(self, kind: str, handler: MessageHandler) -> None:
        """Call ``handler(msg)`` for every message of this type from the vehicle."""
        self._handlers.setdefault(kind, []).append(handler)

    def on_connection(self, handler: Callable[[bool], None]) -> None:
        """Call ``handler(connected)`` when the vehicle is lost or back."""
        self._on_connection.append(handler)

    # -- feeding (called by the Link through the Vehicle) ----------------------------------
    def handle_message(self, msg: mavlink.MAVLink_message) -> None:
        kind = msg.get_type()
        # STATUSTEXT from any component: a camera's or gimbal's warnings matter too
        if msg.get_srcComponent() != self.compid and kind != "STATUSTEXT":
            return
        handlers = self._handlers.get(kind)
        if handlers is None:
            return
        for handler in handlers:
            handler(msg)
        self.updated_s = self.now()
        self.changed()

    def set_connected(
        self, connected: bool, reason: str | None = None, *, silent_since_s: float | None = None
    ) -> None:
        """The link lost the vehicle (``reason``: how it noticed; ``silent_since_s``: when
        it last heard it, if it knows) or heard it again."""
        if connected == self.connected:
            return
        self.connected = connected
        self.lost_reason = None if connected else reason
        if connected:
            lost_for_s = self.now() - self.lost_s if self.lost_s is not None else None
            text = "link to the vehicle back" + (
                f" after {lost_for_s:.1f} s" if lost_for_s is not None else "")
            self.publish_event("connection", {"connected": True, "lost_for_s": lost_for_s,
                                              "text": text})
        else:
            self.lost_s = self.now() if silent_since_s is None else silent_since_s
            text = "link to the vehicle lost" + (f": {reason}" if reason else "")
            self.publish_event("connection", {"connected": False, "reason": reason,
                                              "text": text})
            self.requests.fail_all()
        for handler in self._on_connection:
            handler(connected)
        self.changed()

    def set_link_quality(self, quality: LinkQuality) -> None:
        """The link's figures for this vehicle; a warning that starts, changes or ends is an
        event (``link_quality``) and a state change."""
        previous, self.link_quality = self.link_quality, quality
        before = previous.causes if previous is not None else ()
        if quality.causes == before:
            return
        if quality.degraded:
            text = "link degraded: " + "; ".join(quality.warnings)
        else:
            text = "link quality back to normal"
        self.publish_event("link_quality", {
            "degraded": quality.degraded, "causes": list(quality.causes),
            "loss_in_pct": quality.loss_in_pct, "loss_out_pct": quality.loss_out_pct,
            "silent_s": round(quality.silent_s, 2), "text": text,
        })  # fmt: skip
        self.changed()

    def changed(self) -> None:
        """The state changed: wake waiters and subscribers."""
        self.requests.changed()
        self.hub.notify()

    def _on_heartbeat(self, msg: mavlink.MAVLink_heartbeat_message) -> None:
        self.last_heartbeat_s = self.now()
        self.mav_type = msg.type
        self.autopilot = msg.autopilot

    # -- observing ------------------------------------------------------------------------
    def publish_event(self, kind: str, data: dict[str, object]) -> None:
        self.events.publish(kind, data)


    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Wait until ``predicate()`` holds after some message; False on timeout."""
        return await self.requests.wait_until(predicate, timeout_s)
