"""The server's side of the setpoint sender process (server.link.stream.stream_process).

One process per server, started at the first stream a UDP link hands it: :func:`shared_process`.
A link hands it its socket and, from then on, every frame it sends (:class:`ProcessOut`); a
streamer hands it its stream (:class:`StreamChannel`): the current frame (latest wins) and
the rate. Its reports come back on a reader thread: the frames it wrote (tlog records,
counters, the signing timestamp) to the link, the tick times (the stream's statistics) to
the streamer.

The process is spawned by a keeper thread that lives as long as this process: Linux's
parent-death signal follows the thread that forked, and the loop that first streams may
run on a thread that ends (tests).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import mmap
import os
import pickle
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.signing import LinkSigning
from server.link.codec.signing_keys import signing_timestamp
from server.link.stream import stream_process
from server.link.stream.sender_supervisor import ProcessGone, SenderSupervisor
from server.link.stream.stream_thread import PROCESS_RT_PRIORITY, raise_priority

log = logging.getLogger(__name__)

PROCESS_SCRIPT = Path(__file__).with_name("stream_process.py")
START_TIMEOUT_S = 5.0
MAX_REPORT_BYTES = 1 << 22
# the sender process's last reports of a closing link are waited for this long
DETACH_WAIT_S = 0.5
# messages waiting for a process that does not read (~10 s of 25 Hz sticks) make a fault
MAX_OUTBOX = 256
# at the control socket's end of file, the process's exit status is this close
EXIT_STATUS_WAIT_S = 0.2
# a link taken back signs from the process's last timestamp plus this (10 µs ticks)
SIGNING_MARGIN_TICKS = 1
# how the sender process tells this server's links apart
_link_keys = itertools.count(1)

# (secret key, signing link id, timestamp), or None: not signing
Signing = tuple[bytes, int, int] | None
# the reports of a link: (records [(unix_s, frame)], dropped, signing timestamp)
LinkReports = Callable[[list[tuple[float, bytes]], int, int], None]


class SenderProcess:
    """A running sender process and the server's end of its control socket.

    Nothing here waits on the process: the control socket does not block, a message it
    cannot take now waits in an outbox a writer thread empties (a stream's newer frame
    replaces its queued one), and an outbox that keeps growing is a fault (the process is
    killed). Its death is seen at once, at the control socket's end of file, and reported
    to ``on_gone`` with the cause (its exit status, or why it was killed)."""

    def __init__(self, on_gone: Callable[[Any, str], None] | None = None) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        ours.setblocking(False)
        self._control = ours
        self._on_gone = on_gone
        self._post_lock = threading.Lock()
        self._wake = threading.Condition(self._post_lock)
        # queued messages, in order: [key or None, message, fds]; a keyed one is replaced
        self._outbox: deque[list[Any]] = deque()
        self._links: dict[int, LinkReports] = {}
        self._unlinked: dict[int, threading.Event] = {}
        self._streams: dict[int, Callable[[list[float]], None]] = {}
        self._ids = itertools.count(1)
        self._free_slots = list(range(stream_process.STATE_SLOTS - 1, -1, -1))
        self.alive = True
        self.pid: int | None = None
        self.started_s = time.monotonic()
        self.fault: str | None = None  # why it was killed, when it was
        self._ready = threading.Event()  # its first report came
        self._gone_once = threading.Lock()
        self._ended = threading.Event()  # its end handled: reported, or said in the log
        self._proc: subprocess.Popen[bytes] | None = None
        state_fd = os.memfd_create("skyhelm-sender-state", os.MFD_CLOEXEC)
        os.ftruncate(state_fd, stream_process.STATE_BYTES)
        self._state = mmap.mmap(state_fd, stream_process.STATE_BYTES)
        stream_process.write_heartbeat(self._state, time.monotonic())
        started = threading.Event()
        abandoned = threading.Event()  # the start took too long: nobody owns its process
        start_lock = threading.Lock()
        failure: list[BaseException] = []

        def keep() -> None:
            # this thread forks and then waits: the child's parent-death signal is tied to it
            proc: subprocess.Popen[bytes] | None = None
            try:
                proc = subprocess.Popen(
                    [sys.executable, "-S", "-E", str(PROCESS_SCRIPT), str(os.getpid()),
                     str(PROCESS_RT_PRIORITY), str(theirs.fileno()), str(state_fd)],
                    pass_fds=(theirs.fileno(), state_fd), stdin=subprocess.DEVNULL,
                    close_fds=True)
            except OSError as exc:
                failure.append(exc)
            finally:
                # closed once the fork is done, however long it took: a number passed is
                # never closed, or reused by another file, before the child has its copy
                theirs.close()
                os.close(state_fd)
            with start_lock:
                if proc is not None and not abandoned.is_set():
                    self._proc = proc
                    self.pid = proc.pid
                started.set()
            if proc is None:
                return
            if self._proc is not proc:
                proc.kill()  # started after the server stopped waiting for it
                proc.wait()
                return
            raise_priority()  # after the fork: the exit it waits for hands the streams over
            proc.wait()
            self._gone(self._cause(proc.returncode))

        threading.Thread(target=keep, name="setpoint-process-keeper", daemon=True).start()
        if not started.wait(START_TIMEOUT_S):
            with start_lock:
                if not started.is_set():
                    abandoned.set()
                    failure.append(TimeoutError(f"not started in {START_TIMEOUT_S:g} s"))
        if failure or self.pid is None:
            self.alive = False
            raise ProcessGone(f"cannot start the setpoint sender process: {failure}")
        threading.Thread(target=self._read_reports, name="setpoint-process-reports",
                         daemon=True).start()
        threading.Thread(target=self._write_outbox, name="setpoint-process-writer",
                         daemon=True).start()

    def new_id(self) -> int:
        return next(self._ids)

    # -- to the process --
    def post(self, message: tuple[Any, ...], fds: tuple[int, ...] = (),
             key: Any = None) -> None:
        """Hand ``message`` to the process without waiting: sent now if the socket takes
        it, else queued (a message with the ``key`` of a queued one replaces it: latest
        wins). ProcessGone when the process has ended, or its outbox overflows."""
        with self._post_lock:
            if not self.alive:
                raise ProcessGone("the setpoint sender process has ended")
            try:
                # what waits goes first, as far as the socket takes it now: the outbox grows
                # only while the process does not read, not while the writer thread waits
                # for its turn on a busy server
                self._flush_locked()
                if not self._outbox:
                    self._send_now(message, fds)
                    return
            except BlockingIOError:
                pass
            except OSError as exc:
                self.alive = False
                raise ProcessGone(f"the setpoint sender process has ended ({exc})") from exc
            if key is not None:
                for entry in self._outbox:
                    if entry[0] == key:
                        entry[1] = _merged(entry[1], message)
                        return
            if len(self._outbox) >= MAX_OUTBOX:
                why = (f"its control channel is full ({len(self._outbox)} messages "
                       "waiting): it stopped reading")
                self._kill_locked(why)
                raise ProcessGone(why)
            self._outbox.append([key, message, fds])
            self._wake.notify()

    def _send_now(self, message: tuple[Any, ...], fds: tuple[int, ...]) -> None:
        data = pickle.dumps(message, pickle.HIGHEST_PROTOCOL)
        if fds:
            socket.send_fds(self._control, [data], list(fds))
        else:
            self._control.send(data)

    def _write_outbox(self) -> None:
        poller = select.poll()
        poller.register(self._control, select.POLLOUT)
        while True:
            with self._post_lock:
                while self.alive and not self._outbox:
                    self._wake.wait()
                if not self.alive:
                    self._outbox.clear()
                    return
            poller.poll(50)
            with self._post_lock:
                try:
                    self._flush_locked()
                except BlockingIOError:
                    continue
                except OSError:
                    return  # the reader sees the end of file

    def _flush_locked(self) -> None:
        """Write the queued messages in order until the socket takes no more
        (BlockingIOError); the caller holds the post lock."""
        while self._outbox and self.alive:
            _, message, fds = self._outbox[0]
            self._send_now(message, fds)
            self._outbox.popleft()

    def attach(self, key: int, sock: socket.socket, seq: int, signing: Signing,
               reports: LinkReports) -> int:
        """Hand the link's socket over; answers its slot in the shared state (-1: none)."""
        self._links[key] = reports
        slot = self._free_slots.pop() if self._free_slots else -1
        if slot >= 0:
            stream_process.write_link_state(self._state, _slot_at(slot), seq % 256,
                                            signing[2] if signing else 0)
        self.post(("link", key, seq, signing, slot), (sock.fileno(),))
        return slot

    def link_state(self, slot: int) -> tuple[int, int] | None:
        """(next sequence number, last signing timestamp) the process wrote for a slot."""
        if slot < 0:
            return None
        seq, timestamp = stream_process.STATE_LINK.unpack_from(self._state, _slot_at(slot))
        return int(seq), int(timestamp)

    def detach(self, key: int, wait_s: float, slot: int = -1) -> None:
        """Stop sending for the link; wait up to ``wait_s`` for its last reports."""
        done = self._unlinked[key] = threading.Event()
        with contextlib.suppress(ProcessGone):
            self.post(("unlink", key))
            done.wait(wait_s)
        self._links.pop(key, None)
        self._unlinked.pop(key, None)
        if slot >= 0:
            self._free_slots.append(slot)

    def watch_stream(self, sid: int, ticks: Callable[[list[float]], None]) -> None:
        self._streams[sid] = ticks

    def forget_stream(self, sid: int) -> None:
        self._streams.pop(sid, None)

    # -- its health --
    def wait_ready(self, timeout_s: float) -> bool:
        """Wait until it runs its loop (its first report); False if it did not in time."""
        return self._ready.wait(timeout_s)

    def heartbeat_age_s(self) -> float | None:
        """Seconds since the process last went round its loop (None once it ended)."""
        if not self.alive:
            return None
        # the time first, then the beat: a thread of a busy server can wait long for its
        # turn between two lines, and a beat read before that wait is not this one's age
        now_s = time.monotonic()
        (beat_s,) = stream_process.STATE_HEARTBEAT.unpack_from(self._state, 0)
        # never older than the process itself: a beat not yet written is no silence
        return max(0.0, now_s - max(float(beat_s), self.started_s))

    def kill(self, why: str) -> None:
        """End it for a fault (its end of file then reports ``why``)."""
        with self._post_lock:
            self._kill_locked(why)

    def _kill_locked(self, why: str) -> None:
        if self.fault is None:
            self.fault = why
        if self.pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGKILL)

    def _cause(self, returncode: int | None) -> str:
        if self.fault is not None:
            return f"killed: {self.fault}"
        if returncode is None:
            return "its control socket closed"
        if returncode < 0:
            with contextlib.suppress(ValueError):
                return f"killed by {signal.Signals(-returncode).name}"
        return f"exit status {returncode}"

    # -- from the process --
    def _read_reports(self) -> None:
        raise_priority()  # its end of file hands the streams to the thread: at once
        poller = select.poll()  # not select(): any descriptor number
        poller.register(self._control, select.POLLIN)
        while True:
            try:
                poller.poll()
                data = self._control.recv(MAX_REPORT_BYTES)
            except BlockingIOError:
                continue
            except OSError:
                data = b""
            if not data:
                returncode = None
                if self._proc is not None:
                    # at its end of file it has exited: its status says why
                    with contextlib.suppress(subprocess.TimeoutExpired):
                        returncode = self._proc.wait(EXIT_STATUS_WAIT_S)
                self._gone(self._cause(returncode))
                return
            try:
                self._dispatch(pickle.loads(data))
            except Exception:
                log.exception("setpoint sender process: a report failed")

    def _dispatch(self, report: tuple[Any, ...]) -> None:
        kind = report[0]
        if kind == "sent":
            _, key, records, dropped, timestamp = report
            reports = self._links.get(key)
            if reports is not None:
                reports(records, dropped, timestamp)
        elif kind == "unlinked":
            done = self._unlinked.get(report[1])
            if done is not None:
                done.set()
        elif kind == "ticks":
            ticks = self._streams.get(report[1])
            if ticks is not None:
                ticks(report[2])
        elif kind == "warning":
            log.warning("%s", report[1])
        elif kind == "ready":
            self._ready.set()

    def _gone(self, why: str) -> None:
        if not self._gone_once.acquire(blocking=False):
            return
        with self._post_lock:
            self.alive = False
            unwritten = Counter(message[1] for _, message, _ in self._outbox
                                if message[0] == "send")
            self._outbox.clear()
            self._wake.notify_all()
        for key, frames in unwritten.items():  # never written: dropped, and counted
            reports = self._links.get(key)
            if reports is not None:
                reports([], frames, 0)
        for done in list(self._unlinked.values()):
            done.set()
        if self._on_gone is not None:
            self._ready.set()
            self._on_gone(self, why)
        else:
            log.error("setpoint sender process ended (%s)", why)
        self._ended.set()

    def wait_ended(self, timeout_s: float) -> bool:
        """Whether its end was handled (reported, or said in the log) within ``timeout_s``:
        a caller that killed it waits so before it goes (a test, whose log is closed after)."""
        return self._ended.wait(timeout_s)


def _slot_at(slot: int) -> int:
    return stream_process.STATE_SLOTS_AT + slot * stream_process.STATE_SLOT_BYTES


def _merged(queued: tuple[Any, ...], newer: tuple[Any, ...]) -> tuple[Any, ...]:
    """A stream's queued message with a newer one of the same stream: a queued "stream"
    (send now, re-phase) or "change" (send now) keeps doing so with the newer frame;
    otherwise the newer wins."""
    if queued[0] == "stream" and newer[0] in ("update", "change"):
        _, sid, frame, crc_extra, dests = newer
        return ("stream", sid, queued[2], frame, crc_extra, dests, queued[6])
    if queued[0] == "change" and newer[0] == "update":
        return ("change", *newer[1:])
    return newer


_supervisor: SenderSupervisor | None = None
_supervisor_lock = threading.Lock()


def supervisor() -> SenderSupervisor:
    """This server's sender supervisor (it starts the process when first asked)."""
    global _supervisor
    with _supervisor_lock:
        if _supervisor is None:
            _supervisor = SenderSupervisor(SenderProcess)
        return _supervisor


def sender_status() -> dict[str, Any] | None:
    """The sender process as the API shows it (None: none was ever asked for)."""
    sup = _supervisor
    if sup is None:
        return None
    status = sup.status()
    return {"name": "setpoint sender", "running": status.running, "pid": status.pid,
            "restarts": status.restarts, "faults": status.faults,
            "last_fault": status.last_fault, "gave_up": status.gave_up}


def shared_process() -> SenderProcess:
    """This server's sender process, started when first asked for (ProcessGone if it
    cannot start, or while a process that ended is being replaced)."""
    process = supervisor().process()
    assert isinstance(process, SenderProcess)
    return process


class ProcessOut:
    """A link's frames, sent through the sender process."""

    def __init__(self, process: SenderProcess, key: int, src_system: int, src_component: int
                 ) -> None:
        self.process = process
        self.key = key
        self.slot = -1  # its place in the process's shared state
        # packs unsigned with any sequence number: the process stamps both
        self.packer = mavlink.MAVLink(None, srcSystem=src_system, srcComponent=src_component)

    def frame(self, msg: mavlink.MAVLink_message) -> tuple[bytes, int]:
        return bytes(msg.pack(self.packer)), int(msg.crc_extra)

    def send(self, msg: mavlink.MAVLink_message, dests: list[Any] | None) -> None:
        frame, crc_extra = self.frame(msg)
        self.process.post(("send", self.key, frame, crc_extra, dests))


class StreamChannel:
    """One stream in the sender process: what it sends (latest wins), its rate; the tick
    times come back to ``on_ticks`` (on the reader thread)."""

    def __init__(self, out: ProcessOut, destinations: Callable[[int | None], list[Any] | None],
                 on_ticks: Callable[[int, list[float]], None]) -> None:
        self._out = out
        self._destinations = destinations
        self._on_ticks = on_ticks
        self.sid: int | None = None
        self._last_sid: int | None = None

    @property
    def process(self) -> SenderProcess:
        return self._out.process

    def stream(self, msg: mavlink.MAVLink_message, period_s: float) -> int:
        """Send ``msg`` now and every period from now on; answers the stream's id (a new
        one after a stop, so late reports of the old stream are told apart)."""
        process = self._out.process
        if self.sid is None:
            if self._last_sid is not None:
                process.forget_stream(self._last_sid)
            sid = self.sid = self._last_sid = process.new_id()
            process.watch_stream(sid, lambda times: self._on_ticks(sid, times))
        frame, crc_extra = self._out.frame(msg)
        process.post(("stream", self.sid, self._out.key, frame, crc_extra,
                      self._dests(msg), period_s), key=("stream", self.sid))
        return self.sid

    def update(self, msg: mavlink.MAVLink_message) -> None:
        if self.sid is None:
            return
        frame, crc_extra = self._out.frame(msg)
        self._out.process.post(("update", self.sid, frame, crc_extra, self._dests(msg)),
                               key=("stream", self.sid))

    def change(self, msg: mavlink.MAVLink_message) -> None:
        """Send ``msg`` now in place of the next tick (``Deadlines.early_s``)."""
        if self.sid is None:
            return
        frame, crc_extra = self._out.frame(msg)
        self._out.process.post(("change", self.sid, frame, crc_extra, self._dests(msg)),
                               key=("stream", self.sid))

    def period(self, period_s: float) -> None:
        if self.sid is not None:
            self._out.process.post(("period", self.sid, period_s), key=("period", self.sid))

    def stop(self) -> None:
        sid, self.sid = self.sid, None
        if sid is not None:
            with contextlib.suppress(ProcessGone):
                self._out.process.post(("stop", sid))
            # its last ticks still come (the process reports a stopped stream's ticks)

    def _dests(self, msg: mavlink.MAVLink_message) -> list[Any] | None:
        return self._destinations(getattr(msg, "target_system", None))


class HandOver(Protocol):
    """What a transport offers the sender process (UDP: its socket and peer routing)."""

    def process_socket(self) -> socket.socket | None: ...

    def destinations_of(self, target_system: int | None) -> list[Any] | None: ...


class LinkHandover:
    """A link's sending, handed to the sender process by the first stream there and kept
    there: every frame of the link then goes out through the process (one sequence, one
    signing stream). Reports of what it wrote go to ``on_sent`` on the link's loop.

    When the process is lost (server.link.stream.sender_supervisor) the link takes its
    sending back, from the next sequence number and after the last signing timestamp the
    process wrote; when a new process runs, it hands it over again."""

    def __init__(self, name: str, transport: HandOver, mav: mavlink.MAVLink,
                 signing: LinkSigning, loop: asyncio.AbstractEventLoop,
                 on_sent: LinkReports, lock: threading.Lock | None = None) -> None:
        self._name = name
        self._transport = transport
        self._mav = mav
        self._signing = signing
        self._loop = loop
        self._on_sent = on_sent
        self._lock = lock if lock is not None else threading.Lock()  # the link's send lock
        self.out: ProcessOut | None = None
        self._wanted = False  # a stream asked for the process: handed over whenever it runs
        self._closed = False
        signing.on_key_change = self._signing_changed

    def send(self, msg: mavlink.MAVLink_message, target_system: int | None) -> bool | None:
        """Through the process: True handed over, False no destination (dropped); None
        when the link sends itself (not handed over, or the process has ended)."""
        out = self.out
        if out is None:
            return None
        dests = self._transport.destinations_of(target_system)
        if dests is not None and not dests:
            return False  # no peer has spoken yet
        try:
            out.send(msg, dests)
        except ProcessGone:
            self.sender_lost(out.process)
            return None
        return True

    def channel(self, on_ticks: Callable[[int, list[float]], None],
                lock: threading.Lock | None = None) -> StreamChannel | None:
        """A stream in the process, or None where there is none (a transport without a
        socket to hand over, a process that cannot run or is being replaced)."""
        if self._closed or self._transport.process_socket() is None:
            return None
        self._wanted = True
        supervisor().watch_handover(self)
        out = self.out if self.out is not None else self._hand_over()
        if out is None:
            return None
        return StreamChannel(out, self._transport.destinations_of, on_ticks)

    def _hand_over(self) -> ProcessOut | None:
        sock = self._transport.process_socket()
        if sock is None:
            return None
        try:
            process = shared_process()
            # under the send lock: the sequence handed over is the next one the link uses
            with self._lock:
                if self.out is not None:
                    return self.out
                out = ProcessOut(process, next(_link_keys), self._mav.srcSystem,
                                 self._mav.srcComponent)
                out.slot = process.attach(out.key, sock, self._mav.seq, self._signing_now(),
                                          self._reports)
                self.out = out
                return out
        except ProcessGone as exc:
            log.warning("link %s: setpoints sent by a thread of the server: %s",
                        self._name, exc)
            return None

    # -- the supervisor's --
    def sender_lost(self, process: object) -> None:
        """Send this link's frames here again, from where the process left off."""
        with self._lock:
            out = self.out
            if out is None or out.process is not process:
                return
            self.out = None
            written = out.process.link_state(out.slot)
            if written is not None:
                seq, timestamp = written
                self._mav.seq = seq
                state = self._signing.state
                # never back, never a timestamp used: after the last written, and not behind now
                state.timestamp = max(state.timestamp, timestamp + SIGNING_MARGIN_TICKS,
                                      signing_timestamp())

    def sender_back(self) -> None:
        """A new process runs: hand this link over again if a stream wanted it."""
        if self._wanted and not self._closed and self.out is None:
            self._hand_over()

    def streams_in(self, process: object) -> bool:
        return False

    async def close(self) -> None:
        self._closed = True
        out, self.out = self.out, None
        if out is not None:
            await asyncio.to_thread(out.process.detach, out.key, DETACH_WAIT_S, out.slot)

    def _signing_now(self) -> Signing:
        state = self._signing.state
        if not state.sign_outgoing or state.secret_key is None:
            return None
        return (bytes(state.secret_key), int(state.link_id), int(state.timestamp))

    def _signing_changed(self) -> None:
        out = self.out
        if out is not None:
            with contextlib.suppress(ProcessGone):
                out.process.post(("sign", out.key, self._signing_now()))

    def _reports(self, records: list[tuple[float, bytes]], dropped: int, timestamp: int
                 ) -> None:
        with contextlib.suppress(RuntimeError):  # the loop has closed
            self._loop.call_soon_threadsafe(self._sent, records, dropped, timestamp)

    def _sent(self, records: list[tuple[float, bytes]], dropped: int, timestamp: int) -> None:
        state = self._signing.state
        state.timestamp = max(state.timestamp, timestamp)  # persisted from here
        self._on_sent(records, dropped, timestamp)


_sent_decoder = mavlink.MAVLink(None)  # no signing state: the frames are ours, checked


def decode_sent(frame: bytes) -> mavlink.MAVLink_message | None:
    """A frame the sender process wrote, decoded for the link's frame taps (None if not)."""
    try:
        msg: mavlink.MAVLink_message = _sent_decoder.decode(bytearray(frame))
    except (mavlink.MAVError, ValueError, IndexError):
        return None
    return msg
