"""The vehicles in Foxglove: a Foxglove WebSocket server (foxglove-sdk) on a loopback port,
and per link an MCAP file beside its .tlog, both fed from the same channels.

They live in a process of their own (worker.py): the SDK's calls hold the GIL, at times for
milliseconds while a client is being served, and the setpoint sender thread of this
process needs the GIL to send on time. What stays here is cheap: the link's frame tap
queues each frame (the link's reader waits for nothing), the loop writes them to the
worker in batches, as the .tlog has them; per vehicle, its events, and its state and
health from the API's publisher while the worker says someone reads them.

Bounded on the way: at most PENDING_FRAMES frames wait for the loop, and at most
PIPE_LIMIT_BYTES for a worker that does not keep up; beyond either, frames are dropped
(counted in ``frames_dropped``), never the link slowed. The SDK's server checks no token,
so it binds 127.0.0.1 only; the way in from elsewhere is the app's proxied socket
(proxy.py). Each client's queue is the SDK's (4096 messages, oldest dropped).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import sys
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path

from foxglove.messages import LogLevel
from pymavlink.dialects.v20 import development as mavlink

from server.control.publishers import StatePublishers
from server.control.views import LeaseStatus, finite, state_json, stream_dict
from server.foxglove import wire
from server.foxglove.derived import LEVEL_BY_SEVERITY_NAME
from server.link import Link, Vehicle, VehicleEvent, VehicleState
from server.link.codec.aio import cancel_and_wait

log = logging.getLogger(__name__)

LOOPBACK = "127.0.0.1"
DEFAULT_STATE_RATE_HZ = 50.0
EVENT_BACKLOG = 256
READY_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 10.0
# Frames wait for the next loop iteration in a queue of at most PENDING_FRAMES (beyond it the
# oldest is dropped and counted: only a loop stalled for seconds gets there) and go to the
# worker FRAME_BATCH per iteration, so that timers and reads run between batches.
PENDING_FRAMES = 10_000
FRAME_BATCH = 256
# What may wait in the pipe to the worker before frames are dropped.
PIPE_LIMIT_BYTES = 4 << 20
# Events other than these are information.
_EVENT_LEVELS = {"reboot": LogLevel.Warning, "link_restored": LogLevel.Warning}

Frame = tuple[mavlink.MAVLink_message, bool, float]


class FoxgloveBridge:
    """``port`` None: no WebSocket server; ``record_mcap``: an MCAP file beside each
    link's .tlog. ``await open()`` before the links open, ``attach(link)`` right after each
    Link.open (before anything is read from it: the MCAP file holds what the .tlog
    holds), ``await start(publishers)`` once they are open, ``await close()`` after they
    are closed."""

    def __init__(
        self, *, port: int | None, record_mcap: bool,
        state_rate_hz: float = DEFAULT_STATE_RATE_HZ,
    ) -> None:
        self.requested_port = port
        self.record_mcap = record_mcap
        self.state_rate_hz = state_rate_hz
        self.server_port: int | None = None
        self.mcap_paths: list[Path] = []
        self.readers: set[int] = set()  # system ids whose state or health someone reads
        self._readers_changed = asyncio.Event()
        self._process: asyncio.subprocess.Process | None = None
        self._links: list[tuple[Link, FrameQueue]] = []
        self._tasks: list[asyncio.Task[None]] = []
        self._publishers: StatePublishers | None = None
        self._dropped_in_pipe = 0

    @property
    def port(self) -> int:
        if self.server_port is None:
            raise RuntimeError("the Foxglove server is not running")
        return self.server_port

    @property
    def frames_dropped(self) -> int:
        return self._dropped_in_pipe + sum(queue.dropped for _, queue in self._links)

    async def open(self) -> None:
        port = [] if self.requested_port is None else ["--port", str(self.requested_port)]
        process = self._process = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "server.foxglove.worker", *port,
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
        )
        assert process.stdout is not None
        line = await asyncio.wait_for(process.stdout.readline(), READY_TIMEOUT_S)
        if not line:
            raise RuntimeError("the Foxglove process did not start (see the log above)")
        self.server_port = json.loads(line)["ready"]
        if self.server_port is not None:
            log.info("Foxglove WebSocket server on ws://%s:%d", LOOPBACK, self.server_port)
        self._tasks.append(asyncio.create_task(self._read_worker(process.stdout)))

    def attach(self, link: Link) -> None:
        index = len(self._links)
        mcap = None
        if self.record_mcap and link.tlog_path is not None:
            mcap = link.tlog_path.with_suffix(".mcap")
            self.mcap_paths.append(mcap)
            log.info("recording %s", mcap)
        self._send(wire.record(wire.LINK, index, 0, 0.0, json.dumps(
            {"name": link.name, "mcap": None if mcap is None else str(mcap)}).encode()))
        queue = FrameQueue(lambda frames: self._send_frames(index, frames))
        link.add_frame_tap(queue.put)
        self._links.append((link, queue))

    async def start(self, publishers: StatePublishers) -> None:
        self._publishers = publishers
        for index, (link, _) in enumerate(self._links):
            self._tasks.append(asyncio.create_task(self._discover(index, link)))

    async def close(self) -> None:
        for task in self._tasks:
            await cancel_and_wait(task)
        self._tasks.clear()
        for link, queue in self._links:
            link.remove_frame_tap(queue.put)
            queue.flush()  # what the .tlog recorded goes into the MCAP file too
        self._links.clear()
        process, self._process = self._process, None
        if process is None:
            return
        assert process.stdin is not None
        with contextlib.suppress(ConnectionError):
            await process.stdin.drain()
            process.stdin.close()  # the worker closes its files and ends
        try:
            await asyncio.wait_for(process.wait(), STOP_TIMEOUT_S)
        except TimeoutError:
            process.kill()
            await process.wait()
        self.server_port = None

    # -- to the worker -------------------------------------------------------------------

    def _send(self, data: bytes) -> bool:
        process = self._process
        if process is None or process.stdin is None or process.stdin.is_closing():
            return False
        if process.stdin.transport.get_write_buffer_size() > PIPE_LIMIT_BYTES:
            return False
        process.stdin.write(data)
        return True

    def _send_frames(self, link: int, frames: list[Frame]) -> None:
        data = b"".join(
            wire.record(wire.FRAME, link, sent, unix_time_s, msg.get_msgbuf())
            for msg, sent, unix_time_s in frames
        )
        if not self._send(data):
            self._dropped_in_pipe += len(frames)

    # -- from the worker -----------------------------------------------------------------

    async def _read_worker(self, stdout: asyncio.StreamReader) -> None:
        while line := await stdout.readline():
            readers = json.loads(line).get("readers")
            if readers is not None:
                self.readers = set(readers)
                self._readers_changed.set()
        log.warning("the Foxglove process ended")

    # -- per vehicle ---------------------------------------------------------------------

    async def _discover(self, index: int, link: Link) -> None:
        queue = link.subscribe_vehicles()
        watched: set[int] = set()
        try:
            while True:
                vehicle = await queue.get()
                if vehicle.sysid in watched:
                    continue
                watched.add(vehicle.sysid)
                self._send(wire.record(wire.VEHICLE, index, vehicle.sysid, 0.0, b""))
                self._tasks.append(asyncio.create_task(self._states(index, vehicle)))
                self._tasks.append(asyncio.create_task(self._events(index, vehicle)))
        finally:
            link.unsubscribe_vehicles(queue)

    async def _states(self, index: int, vehicle: Vehicle) -> None:
        """State and health at state_rate_hz while the worker says someone reads them."""
        assert self._publishers is not None
        while True:
            while vehicle.sysid not in self.readers:
                self._readers_changed.clear()
                await self._readers_changed.wait()
            publisher = self._publishers.for_vehicle(vehicle)
            slot = publisher.subscribe(self.state_rate_hz)
            try:
                async for published in slot:
                    self._send_state(index, published.state, published.body, published.lease)
                    if vehicle.sysid not in self.readers:
                        break
            finally:
                publisher.unsubscribe(slot)
            if vehicle.sysid in self.readers:  # the vehicle's publisher went away
                await asyncio.sleep(1.0)

    def _send_state(
        self, index: int, state: VehicleState, body: bytes, lease: LeaseStatus
    ) -> None:
        now_s = _unix_time_s()
        health = {"stream": stream_dict(state.stream),
                  "link": finite(dataclasses.asdict(state.link))}
        self._send(wire.record(wire.STATE, index, state.sysid, now_s,
                               state_json(state, body, lease)))
        self._send(wire.record(wire.HEALTH, index, state.sysid, now_s,
                               json.dumps(health, separators=(",", ":")).encode()))

    async def _events(self, index: int, vehicle: Vehicle) -> None:
        queue = vehicle.subscribe_events(EVENT_BACKLOG)
        try:
            while True:
                event = await queue.get()
                if event.kind == "statustext":  # the worker logs STATUSTEXT frames
                    continue
                level, text = event_log(event)
                line = [vehicle.sysid, level.value, f"skyhelm.{event.kind}", text]
                self._send(wire.record(wire.EVENT, index, 0, event.time_s,
                                       json.dumps(line).encode()))
        finally:
            vehicle.unsubscribe_events(queue)


class FrameQueue:
    """A link's frames on their way out: the tap puts, the loop hands them on soon after,
    in order, FRAME_BATCH at a time."""

    def __init__(self, send: Callable[[list[Frame]], None]) -> None:
        self._send = send
        self._loop = asyncio.get_running_loop()
        self._pending: deque[Frame] = deque()
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
        pending = self._pending
        self._send([pending.popleft() for _ in range(min(FRAME_BATCH, len(pending)))])
        if pending and not self._scheduled:
            self._scheduled = True
            self._loop.call_soon(self._drain)

    def flush(self) -> None:
        while self._pending:
            self._drain()


def _unix_time_s() -> float:
    return time.time()


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
