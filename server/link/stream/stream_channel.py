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
import os
import pickle
import socket
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.signing import LinkSigning
from server.link.stream.stream_thread import PROCESS_RT_PRIORITY

log = logging.getLogger(__name__)

PROCESS_SCRIPT = Path(__file__).with_name("stream_process.py")
START_TIMEOUT_S = 5.0
MAX_REPORT_BYTES = 1 << 22
# the sender process's last reports of a closing link are waited for this long
DETACH_WAIT_S = 0.5
# how the sender process tells this server's links apart
_link_keys = itertools.count(1)

# (secret key, signing link id, timestamp), or None: not signing
Signing = tuple[bytes, int, int] | None
# the reports of a link: (records [(unix_s, frame)], dropped, signing timestamp)
LinkReports = Callable[[list[tuple[float, bytes]], int, int], None]


class ProcessGone(RuntimeError):
    """The sender process is not running (it could not start, or it died)."""


class SenderProcess:
    """The running sender process and the server's end of its control socket."""

    def __init__(self) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self._control = ours
        self._post_lock = threading.Lock()
        self._links: dict[int, LinkReports] = {}
        self._unlinked: dict[int, threading.Event] = {}
        self._streams: dict[int, Callable[[list[float]], None]] = {}
        self._ids = itertools.count(1)
        self.alive = True
        self.pid: int | None = None
        started = threading.Event()
        failure: list[BaseException] = []

        def keep() -> None:
            # this thread forks and then waits: the child's parent-death signal is tied to it
            try:
                proc = subprocess.Popen(
                    [sys.executable, "-S", "-E", str(PROCESS_SCRIPT), str(os.getpid()),
                     str(PROCESS_RT_PRIORITY), str(theirs.fileno())],
                    pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, close_fds=True)
            except OSError as exc:
                failure.append(exc)
                started.set()
                return
            self.pid = proc.pid
            started.set()
            proc.wait()
            self._gone(f"exit status {proc.returncode}")

        threading.Thread(target=keep, name="setpoint-process-keeper", daemon=True).start()
        started.wait(START_TIMEOUT_S)
        theirs.close()
        if failure or self.pid is None:
            self.alive = False
            raise ProcessGone(f"cannot start the setpoint sender process: {failure}")
        threading.Thread(target=self._read_reports, name="setpoint-process-reports",
                         daemon=True).start()

    def new_id(self) -> int:
        return next(self._ids)

    # -- to the process --
    def post(self, message: tuple[Any, ...], fds: tuple[int, ...] = ()) -> None:
        data = pickle.dumps(message, pickle.HIGHEST_PROTOCOL)
        with self._post_lock:
            if not self.alive:
                raise ProcessGone("the setpoint sender process has ended")
            try:
                socket.send_fds(self._control, [data], list(fds))
            except OSError as exc:
                self._gone(str(exc))
                raise ProcessGone(f"the setpoint sender process has ended ({exc})") from exc

    def attach(self, key: int, sock: socket.socket, seq: int, signing: Signing,
               reports: LinkReports) -> None:
        self._links[key] = reports
        self.post(("link", key, seq, signing), (sock.fileno(),))

    def detach(self, key: int, wait_s: float) -> None:
        """Stop sending for the link; wait up to ``wait_s`` for its last reports."""
        done = self._unlinked[key] = threading.Event()
        with contextlib.suppress(ProcessGone):
            self.post(("unlink", key))
            done.wait(wait_s)
        self._links.pop(key, None)
        self._unlinked.pop(key, None)

    def watch_stream(self, sid: int, ticks: Callable[[list[float]], None]) -> None:
        self._streams[sid] = ticks

    def forget_stream(self, sid: int) -> None:
        self._streams.pop(sid, None)

    # -- from the process --
    def _read_reports(self) -> None:
        while True:
            try:
                data = self._control.recv(MAX_REPORT_BYTES)
            except OSError:
                data = b""
            if not data:
                self._gone("its control socket closed")
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

    def _gone(self, why: str) -> None:
        with self._post_lock:
            was_alive, self.alive = self.alive, False
        if was_alive:
            log.error("setpoint sender process ended (%s): links it sent for go back to "
                      "sending themselves; its streams stop", why)
        for done in list(self._unlinked.values()):
            done.set()


_shared: SenderProcess | None = None
_shared_lock = threading.Lock()


def shared_process() -> SenderProcess:
    """This server's sender process, started when first asked for (ProcessGone if it
    cannot start; a process that ended is not started again)."""
    global _shared
    with _shared_lock:
        if _shared is None:
            _shared = SenderProcess()
        if not _shared.alive:
            raise ProcessGone("the setpoint sender process has ended")
        return _shared


class ProcessOut:
    """A link's frames, sent through the sender process."""

    def __init__(self, process: SenderProcess, key: int, src_system: int, src_component: int
                 ) -> None:
        self.process = process
        self.key = key
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
                      self._dests(msg), period_s))
        return self.sid

    def update(self, msg: mavlink.MAVLink_message) -> None:
        if self.sid is None:
            return
        frame, crc_extra = self._out.frame(msg)
        self._out.process.post(("update", self.sid, frame, crc_extra, self._dests(msg)))

    def period(self, period_s: float) -> None:
        if self.sid is not None:
            self._out.process.post(("period", self.sid, period_s))

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
    signing stream). Reports of what it wrote go to ``on_sent`` on the link's loop."""

    def __init__(self, name: str, transport: HandOver, mav: mavlink.MAVLink,
                 signing: LinkSigning, loop: asyncio.AbstractEventLoop,
                 on_sent: LinkReports) -> None:
        self._name = name
        self._transport = transport
        self._mav = mav
        self._signing = signing
        self._loop = loop
        self._on_sent = on_sent
        self.out: ProcessOut | None = None
        self._refused = False  # the process could not take this link: not asked again
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
            self.out = None
            return None
        return True

    def channel(self, on_ticks: Callable[[int, list[float]], None], lock: threading.Lock
                ) -> StreamChannel | None:
        """A stream in the process, or None where there is none (a transport without a
        socket to hand over, or a process that cannot run). ``lock`` is the link's send
        lock: the sequence number handed over is the last one the link used."""
        if self._refused:
            return None
        if self.out is None:
            sock = self._transport.process_socket()
            if sock is None:
                return None
            try:
                process = shared_process()
                with lock:
                    out = ProcessOut(process, next(_link_keys), self._mav.srcSystem,
                                     self._mav.srcComponent)
                    process.attach(out.key, sock, self._mav.seq, self._signing_now(),
                                   self._reports)
                    self.out = out
            except ProcessGone as exc:
                self._refused = True
                log.warning("link %s: setpoints sent by a thread of the server: %s",
                            self._name, exc)
                return None
        return StreamChannel(self.out, self._transport.destinations_of, on_ticks)

    async def close(self) -> None:
        out, self.out = self.out, None
        if out is not None:
            await asyncio.to_thread(out.process.detach, out.key, DETACH_WAIT_S)

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
