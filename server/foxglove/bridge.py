"""The vehicles in Foxglove: a Foxglove WebSocket server (foxglove-sdk) on a loopback port,
and per link an MCAP file beside its .tlog, both fed from the same channels.

What feeds them: every frame of a link through a frame tap (router.py; the tap only queues
the frame, so the link's reader does not wait for any encoding), and per vehicle
its events (foxglove.Log) and, while someone reads them, its state and health from the
API's state publisher at ``state_rate_hz``. Nothing is encoded for a channel without a
reader, so with no client and no MCAP file the bridge costs a lookup per frame.

The SDK's server checks no token, so it binds 127.0.0.1 only; the authenticated way in
from elsewhere is the app's proxied socket (proxy.py). Its send queue per client is the
SDK's (``message_backlog_size``): a slow client loses its oldest messages.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import logging
import time
from collections import deque
from pathlib import Path

import foxglove
from foxglove.messages import LogLevel
from foxglove.websocket import WebSocketServer
from pymavlink.dialects.v20 import development as mavlink

from server.api.publisher import StatePublishers
from server.api.views import LeaseStatus, finite, state_json, stream_dict
from server.foxglove.channels import LINK_METADATA, LinkChannels, VehicleChannels
from server.foxglove.derived import LEVEL_BY_SEVERITY_NAME
from server.foxglove.router import FrameRouter
from server.link import Link, Vehicle, VehicleEvent, VehicleState
from server.link.aio import cancel_and_wait
from server.link.link import FrameTap

log = logging.getLogger(__name__)

LOOPBACK = "127.0.0.1"
DEFAULT_STATE_RATE_HZ = 50.0
# How often a vehicle's state and health channels are looked at for a new reader.
READER_CHECK_S = 0.25
EVENT_BACKLOG = 256
# Each client's queue in the SDK's server: the oldest data message goes when it is full.
MESSAGE_BACKLOG = 4096
# Frames wait for the next loop iteration in a queue of at most PENDING_FRAMES (beyond it the
# oldest is dropped and counted: only a loop stalled for seconds gets there) and are routed
# FRAME_BATCH per iteration, so that timers and reads run between batches.
PENDING_FRAMES = 10_000
FRAME_BATCH = 64
# Events other than these are information.
_EVENT_LEVELS = {"reboot": LogLevel.Warning, "link_restored": LogLevel.Warning}


class FoxgloveBridge:
    """``port`` None: no WebSocket server; ``record_mcap``: an MCAP file beside each
    link's .tlog. ``attach(link)`` right after Link.open, before anything is read from it,
    so the MCAP file holds what the .tlog holds; ``start(publishers)`` once the links are
    open; ``close()`` after they are closed."""

    def __init__(
        self, *, port: int | None, record_mcap: bool,
        state_rate_hz: float = DEFAULT_STATE_RATE_HZ,
    ) -> None:
        self.context = foxglove.Context()
        self.requested_port = port
        self.record_mcap = record_mcap
        self.state_rate_hz = state_rate_hz
        self.server: WebSocketServer | None = None
        self.mcap_paths: list[Path] = []
        self._links: list[tuple[Link, LinkChannels, FrameRouter, FrameQueue]] = []
        self._writers: list[foxglove.MCAPWriter] = []
        self._tasks: list[asyncio.Task[None]] = []
        self._publishers: StatePublishers | None = None

    @property
    def port(self) -> int:
        if self.server is None:
            raise RuntimeError("the Foxglove server is not running")
        port: int = self.server.port
        return port

    def attach(self, link: Link) -> None:
        channels = LinkChannels(self.context, link.name)
        router = FrameRouter(channels)
        queue = FrameQueue(router.frame)
        link.add_frame_tap(queue.put)
        self._links.append((link, channels, router, queue))
        if self.record_mcap and link.tlog_path is not None:
            self._open_mcap(link.tlog_path.with_suffix(".mcap"), link.name)

    def _open_mcap(self, path: Path, link_name: str) -> None:
        def this_link(channel: foxglove.ChannelDescriptor) -> bool:
            return channel.metadata.get(LINK_METADATA) == link_name

        self._writers.append(
            foxglove.open_mcap(path, context=self.context, channel_filter=this_link)
        )
        self.mcap_paths.append(path)
        log.info("recording %s", path)

    async def start(self, publishers: StatePublishers) -> None:
        self._publishers = publishers
        if self.requested_port is not None:
            self.server = foxglove.start_server(
                name="SkyHelm", host=LOOPBACK, port=self.requested_port, context=self.context,
                message_backlog_size=MESSAGE_BACKLOG,
            )
            log.info("Foxglove WebSocket server on ws://%s:%d", LOOPBACK, self.server.port)
        for link, channels, router, _ in self._links:
            self._tasks.append(asyncio.create_task(self._discover(link, channels, router)))

    async def close(self) -> None:
        for task in self._tasks:
            await cancel_and_wait(task)
        self._tasks.clear()
        if self.server is not None:
            self.server.stop()
            self.server = None
        for link, _, _, queue in self._links:
            link.remove_frame_tap(queue.put)
            queue.flush()  # what the .tlog recorded goes into the MCAP file too
        for writer in self._writers:
            writer.close()
        self._writers.clear()
        for _, channels, _, _ in self._links:
            channels.close()
        self._links.clear()

    @property
    def frames_dropped(self) -> int:
        return sum(queue.dropped for *_, queue in self._links)

    async def _discover(self, link: Link, channels: LinkChannels, router: FrameRouter) -> None:
        queue = link.subscribe_vehicles()
        watched: set[int] = set()
        try:
            while True:
                vehicle = await queue.get()
                if vehicle.sysid in watched:
                    continue
                watched.add(vehicle.sysid)
                self._tasks.append(asyncio.create_task(self._states(vehicle, channels)))
                self._tasks.append(asyncio.create_task(self._events(vehicle, router)))
        finally:
            link.unsubscribe_vehicles(queue)

    async def _states(self, vehicle: Vehicle, link: LinkChannels) -> None:
        """State and health while either has a reader, at state_rate_hz."""
        assert self._publishers is not None
        channels = link.vehicle(vehicle.sysid)
        while True:
            if not _read(channels):
                await asyncio.sleep(READER_CHECK_S)
                continue
            publisher = self._publishers.for_vehicle(vehicle)
            slot = publisher.subscribe(self.state_rate_hz)
            try:
                async for published in slot:
                    _log_state(channels, published.state, published.body,
                               published.lease)
                    if not _read(channels):
                        break
            finally:
                publisher.unsubscribe(slot)
            await asyncio.sleep(READER_CHECK_S)  # the vehicle went away, or nobody reads

    async def _events(self, vehicle: Vehicle, router: FrameRouter) -> None:
        derived = router.derived(vehicle.sysid)
        queue = vehicle.subscribe_events(EVENT_BACKLOG)
        try:
            while True:
                event = await queue.get()
                if event.kind != "statustext":  # STATUSTEXT frames are logged as they come
                    level, text = event_log(event)
                    derived.log(level, text, f"skyhelm.{event.kind}", int(event.time_s * 1e9))
        finally:
            vehicle.unsubscribe_events(queue)


class FrameQueue:
    """A link's frames on their way to the router: the tap puts, the loop routes them soon
    after, in order, FRAME_BATCH at a time."""

    def __init__(self, route: FrameTap) -> None:
        self._route = route
        self._loop = asyncio.get_running_loop()
        self._pending: deque[tuple[mavlink.MAVLink_message, bool, float]] = deque()
        self._scheduled = False
        self.dropped = 0

    def put(self, msg: mavlink.MAVLink_message, sent: bool, unix_time_s: float) -> None:
        pending = self._pending
        if len(pending) >= PENDING_FRAMES:
            pending.popleft()
            self.dropped += 1
        pending.append((msg, sent, unix_time_s))
        if not self._scheduled:
            self._scheduled = True
            self._loop.call_soon(self._drain)

    def _drain(self) -> None:
        self._scheduled = False
        pending, route = self._pending, self._route
        for _ in range(min(FRAME_BATCH, len(pending))):
            route(*pending.popleft())
        if pending and not self._scheduled:
            self._scheduled = True
            self._loop.call_soon(self._drain)

    def flush(self) -> None:
        while self._pending:
            self._route(*self._pending.popleft())


def _read(channels: VehicleChannels) -> bool:
    return channels.state.has_sinks() or channels.health.has_sinks()


def _log_state(
    channels: VehicleChannels, state: VehicleState, body: bytes, lease: LeaseStatus
) -> None:
    time_ns = time.time_ns()
    if channels.state.has_sinks():
        channels.state.base.log(state_json(state, body, lease), time_ns)
    if channels.health.has_sinks():
        health = {"stream": stream_dict(state.stream),
                  "link": finite(dataclasses.asdict(state.link))}
        channels.health.base.log(json.dumps(health, separators=(",", ":")).encode(), time_ns)


def event_log(event: VehicleEvent) -> tuple[LogLevel, str]:
    """An event as a log line: its own text where it has one, else its kind and data."""
    data = event.data
    level = LEVEL_BY_SEVERITY_NAME.get(str(data.get("severity", "")).upper())
    if level is None:
        lost = event.kind == "connection" and data.get("connected") is False
        level = LogLevel.Warning if lost else _EVENT_LEVELS.get(event.kind, LogLevel.Info)
    text = data.get("text")
    if not isinstance(text, str):
        text = f"{event.kind}: {json.dumps(data, default=str, separators=(', ', ': '))}"
    return level, text
