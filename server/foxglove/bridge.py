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

The worker is supervised: its end is seen at once (its stdout's end of file), logged once
with the cause, told to ``on_change`` listeners (the vehicles' ``process`` event) and shown
by ``status()``; it is started again after a back-off (``RESTART_BACKOFF_S``; after
``MAX_FAILED_RESTARTS`` quick failures in a row it is not), on the same port when one was
asked for (the proxied route follows the new one either way: clients reconnect), with the
links, vehicles and recording as they were: each link's recording goes on in a new MCAP
part beside the first (``name.1.mcap``, ...). A spare worker waits, its imports done
(``--standby``), so a restart takes milliseconds, not the seconds a new Python process takes
on a busy machine; a new spare follows each restart. The worker finishes an MCAP chunk at
least every ``MCAP_FLUSH_S`` (worker.py), so a crash loses at most about that much of it.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import signal
import sys
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

from foxglove.messages import LogLevel
from pymavlink.dialects.v20 import development as mavlink

from server.control.publishers import StatePublishers
from server.control.slots import EVENT_BACKLOG
from server.control.views import LeaseStatus, finite, state_json, stream_dict
from server.foxglove import wire
from server.foxglove.derived import LEVEL_BY_SEVERITY_NAME
from server.link import Link, Vehicle, VehicleEvent, VehicleState
from server.link.codec.aio import cancel_and_wait

log = logging.getLogger(__name__)

LOOPBACK = "127.0.0.1"
DEFAULT_STATE_RATE_HZ = 50.0
READY_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 10.0
# Frames wait for the next loop iteration in a queue of at most PENDING_FRAMES (beyond it the
# oldest is dropped and counted: only a loop stalled for seconds gets there) and go to the
# worker FRAME_BATCH per iteration, so that timers and reads run between batches.
PENDING_FRAMES = 10_000
FRAME_BATCH = 256
# What may wait in the pipe to the worker before frames are dropped.
PIPE_LIMIT_BYTES = 4 << 20
# A worker that ends is started again after these delays (quick failures in a row pick the
# next; one that ran STABLE_AFTER_S starts the count again); after all of them, never.
RESTART_BACKOFF_S = (0.0, 1.0, 4.0)
MAX_FAILED_RESTARTS = len(RESTART_BACKOFF_S)
STABLE_AFTER_S = 10.0
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
        # supervision: what the API shows, and who hears of a fault or recovery
        self.restarts = 0
        self.faults = 0
        self.last_fault: str | None = None
        self.gave_up = False
        self.on_change: list[Callable[[dict[str, Any]], None]] = []
        self._closing = False
        self._failed_in_row = 0
        self._started_s = 0.0
        self._mcaps: list[Path | None] = []  # per link: where its recording began
        self._vehicles: list[tuple[int, int]] = []  # (link index, sysid) the worker was told
        self._standby: asyncio.subprocess.Process | None = None  # a spare, imports done
        self._standby_ready: asyncio.Task[bool] | None = None

    @property
    def port(self) -> int:
        if self.server_port is None:
            raise RuntimeError("the Foxglove server is not running")
        return self.server_port

    @property
    def frames_dropped(self) -> int:
        return self._dropped_in_pipe + sum(queue.dropped for _, queue in self._links)

    async def open(self) -> None:
        await self._spawn(self.requested_port)

    async def _spawn(self, port_wanted: int | None) -> None:
        process = await self._take_standby(port_wanted)
        if process is None:
            port = [] if port_wanted is None else ["--port", str(port_wanted)]
            process = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "server.foxglove.worker", *port,
                stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
            )
        self._process = process
        assert process.stdout is not None
        line = await asyncio.wait_for(process.stdout.readline(), READY_TIMEOUT_S)
        if not line:
            raise RuntimeError("the Foxglove process did not start (see the log above)")
        self.server_port = json.loads(line)["ready"]
        self._started_s = time.monotonic()
        if self.server_port is not None:
            log.info("Foxglove WebSocket server on ws://%s:%d", LOOPBACK, self.server_port)
        self._tasks.append(asyncio.create_task(self._read_worker(process, process.stdout)))
        self._start_standby()

    def _start_standby(self) -> None:
        async def start() -> bool:
            standby = self._standby = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "server.foxglove.worker", "--standby",
                stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
            )
            assert standby.stdout is not None
            line = await standby.stdout.readline()
            return bool(line) and json.loads(line).get("standby") is True

        if self._standby is None and not self._closing:
            self._standby_ready = asyncio.create_task(start())

    async def _take_standby(self, port: int | None) -> asyncio.subprocess.Process | None:
        """The spare worker, told its port, if it is ready (else it is ended)."""
        standby, ready = self._standby, self._standby_ready
        self._standby = self._standby_ready = None
        if standby is None or ready is None:
            return None
        if not ready.done() or ready.exception() is not None or not ready.result() \
                or standby.returncode is not None:
            log.info("the spare Foxglove worker was not ready: starting a new one")
            await self._end_standby(standby, ready)
            return None
        assert standby.stdin is not None
        standby.stdin.write(json.dumps({"port": port}).encode() + b"\n")
        return standby

    async def _end_standby(self, standby: asyncio.subprocess.Process | None,
                           ready: asyncio.Task[bool] | None) -> None:
        await cancel_and_wait(ready)
        if standby is not None and standby.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                standby.kill()
            await standby.wait()

    @property
    def spare_ready(self) -> bool:
        """Whether a spare worker waits, ready to take over at once."""
        ready = self._standby_ready
        return (ready is not None and ready.done() and ready.exception() is None
                and ready.result())

    def status(self) -> dict[str, Any]:
        """The worker as the API shows it."""
        process = self._process
        running = process is not None and process.returncode is None
        return {"name": "foxglove worker", "running": running,
                "pid": process.pid if running and process is not None else None,
                "restarts": self.restarts, "faults": self.faults,
                "last_fault": self.last_fault, "gave_up": self.gave_up}

    def attach(self, link: Link) -> None:
        index = len(self._links)
        mcap = None
        if self.record_mcap and link.tlog_path is not None:
            mcap = link.tlog_path.with_suffix(".mcap")
            self.mcap_paths.append(mcap)
            log.info("recording %s", mcap)
        self._mcaps.append(mcap)
        self._send_link(index, link.name, mcap)
        queue = FrameQueue(lambda frames: self._send_frames(index, frames))
        link.add_frame_tap(queue.put)
        self._links.append((link, queue))

    async def start(self, publishers: StatePublishers) -> None:
        self._publishers = publishers
        for index, (link, _) in enumerate(self._links):
            self._tasks.append(asyncio.create_task(self._discover(index, link)))

    def _send_link(self, index: int, name: str, mcap: Path | None) -> None:
        self._send(wire.record(wire.LINK, index, 0, 0.0, json.dumps(
            {"name": name, "mcap": None if mcap is None else str(mcap)}).encode()))

    async def close(self) -> None:
        self._closing = True
        standby, ready = self._standby, self._standby_ready
        self._standby = self._standby_ready = None
        await self._end_standby(standby, ready)
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

    async def _read_worker(self, process: asyncio.subprocess.Process,
                           stdout: asyncio.StreamReader) -> None:
        while line := await stdout.readline():
            readers = json.loads(line).get("readers")
            if readers is not None:
                self.readers = set(readers)
                self._readers_changed.set()
        if self._closing or process is not self._process:
            return
        # its end of file: it has exited (or is about to); its status says why
        returncode = await process.wait()
        await self._worker_ended(_cause(returncode))

    async def _worker_ended(self, why: str) -> None:
        stable = time.monotonic() - self._started_s >= STABLE_AFTER_S
        self._failed_in_row = 1 if stable else self._failed_in_row + 1
        self.faults += 1
        self.last_fault = why
        self.gave_up = self._failed_in_row > MAX_FAILED_RESTARTS
        self.readers = set()
        self._readers_changed.set()
        delay_s = RESTART_BACKOFF_S[min(self._failed_in_row, len(RESTART_BACKOFF_S)) - 1]
        log.error("the Foxglove process ended (%s): live view and MCAP recording stop%s", why,
                  "; it failed too often and is not started again" if self.gave_up
                  else f" until it is restarted in {delay_s:g} s")
        self._tell({"running": False, "fault": why})
        if self.gave_up:
            return
        await asyncio.sleep(delay_s)
        if self._closing:
            return
        # the same port when one was asked for, else a new one (the proxy follows it)
        try:
            await self._spawn(self.requested_port)
        except (OSError, RuntimeError, TimeoutError) as exc:
            self._tasks.append(asyncio.create_task(self._worker_ended(f"cannot restart: {exc}")))
            return
        self.restarts += 1
        for index, (link, _) in enumerate(self._links):
            mcap = self._mcaps[index]
            if mcap is not None:
                mcap = _next_part(mcap)
                self.mcap_paths.append(mcap)
                log.info("recording goes on in %s", mcap)
            self._send_link(index, link.name, mcap)
        for index, sysid in self._vehicles:
            self._send(wire.record(wire.VEHICLE, index, sysid, 0.0, b""))
        log.warning("the Foxglove process restarted (pid %s)", self._process.pid
                    if self._process is not None else None)
        self._tell({"running": True, "recovered": True})

    def _tell(self, change: dict[str, Any]) -> None:
        text = ("Foxglove worker restarted: live view and MCAP recording go on"
                if change.get("recovered") else
                f"Foxglove worker ended ({change.get('fault')}): "
                + ("not restarted again" if self.gave_up else "restarting it"))
        data = {"process": "foxglove worker", **change, "restarts": self.restarts,
                "gave_up": self.gave_up, "text": text}
        for listener in list(self.on_change):
            try:
                listener(data)
            except Exception:
                log.exception("a Foxglove status listener failed")

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
                self._vehicles.append((index, vehicle.sysid))
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


def _cause(returncode: int) -> str:
    if returncode < 0:
        with contextlib.suppress(ValueError):
            return f"killed by {signal.Signals(-returncode).name}"
    return f"exit status {returncode}"


def _next_part(path: Path) -> Path:
    """``name.mcap`` -> ``name.1.mcap`` -> ``name.2.mcap``: the first free one."""
    stem = path.name.removesuffix(".mcap")
    for part in range(1, 10_000):
        candidate = path.with_name(f"{stem}.{part}.mcap")
        if not candidate.exists():
            return candidate
    raise RuntimeError(f"no free MCAP part beside {path}")


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
