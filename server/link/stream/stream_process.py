"""The setpoint sender process: every frame a server's UDP links send, and the streams' ticks.

A stream timed by a thread of the server still needs the GIL to send, and the thread holding
it may have been preempted: on a machine with busy cores a tick then waits for the OS to
run the server again. This process holds no GIL but its own and runs no event loop: it
sleeps until the earliest deadline of any stream, at real-time priority (SCHED_FIFO) where
the OS allows it, and sends. It waits with poll(), so any descriptor number works (a
server with more than 1024 open sockets hands over fds above FD_SETSIZE).

It owns the sending side of each link it is given (the link's own UDP socket, passed over
the control socket, so the source port is the link's): the MAVLink sequence number and,
with a key, the signing timestamp. Every frame of such a link goes out here, the server's
own (commands, heartbeats) and the streams' ticks alike, so sequence numbers stay
contiguous on the wire and one signing stream (link id, system, component) keeps rising
timestamps. The server packs frames unsigned; each is re-stamped here (sequence, CRC, then
signature) as it is written.

Stdlib only, run by path (``python -S stream_process.py``): it starts in milliseconds and
imports nothing of the server. The control socket (SOCK_SEQPACKET, its fd the third
argument) carries pickled tuples; the server's messages:

- ``("link", key, seq, signing[, slot])`` + the socket's fd: a link to send for;
  ``signing`` is ``(secret_key, link_id, timestamp)`` or None; ``slot`` its place in the
  shared state (or -1); ``("unlink", key)``;
- ``("sign", key, signing)``: the link's key changed;
- ``("send", key, frame, crc_extra, dests)``: write once (dests: addresses, or None on a
  connected socket);
- ``("stream", sid, key, frame, crc_extra, dests, period_s)``: send now and then every
  period on t0 + k·period; ``("update", sid, frame, crc_extra, dests)`` changes what the
  next tick sends; ``("change", sid, frame, crc_extra, dests)`` sends a changed frame now
  in place of the next tick (:meth:`Deadlines.early_s`: the ticks after it keep their
  times, so the rate stays); ``("period", sid, period_s)`` re-phases from the last send;
  ``("stop", sid)``.

Its reports, batched every ``REPORT_PERIOD_S``: ``("sent", key, [(unix_s, frame)], dropped,
signing_timestamp)`` (the tlog records and counters), ``("ticks", sid, [monotonic_s])``
(the stream's statistics, on the same CLOCK_MONOTONIC as the server's), ``("unlinked",
key)`` once a link's last frames are reported, and once, if it
cannot have real-time scheduling, ``("warning", text)``. Its first report, at once, is
``("ready", pid)``.

The optional fourth argument is a shared memory file (memfd) it keeps current for the
server's supervisor (server.link.stream.sender_supervisor): at offset 0 the CLOCK_MONOTONIC
time of its last loop (``<d``; a stuck process stops moving it), and per link slot (the
``slot`` of the "link" message, ``STATE_SLOT_BYTES`` each from ``STATE_SLOTS_AT``) the next
sequence number and the last signing timestamp it wrote (``<IQ``), so a server that takes
the link back after this process died goes on from the last frame actually written.

It ends when the server does: at the control socket's end of file, and by
PR_SET_PDEATHSIG (SIGKILL) should the server die without closing it.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import hashlib
import heapq
import itertools
import math
import mmap
import os
import pickle
import select
import signal
import socket
import struct
import sys
import time
from collections.abc import Iterable
from typing import Any

# Reports (sent frames, tick times) go back this often; the server's figures lag this much.
REPORT_PERIOD_S = 0.05
MAX_CONTROL_MESSAGE_BYTES = 1 << 16
PR_SET_PDEATHSIG = 1
MAVLINK_STX_V2 = 0xFD
MAVLINK_IFLAG_SIGNED = 0x01
MAVLINK_SIGNATURE_BLOCK_LEN = 13
# MAVLink signing timestamps count 10 µs since 2015-01-01T00:00:00Z.
SIGNING_EPOCH_UNIX_S = 1_420_070_400
SIGNING_TICKS_PER_S = 100_000
# Unsent reports kept while the server does not read them; older tlog records go first.
MAX_PENDING_RECORDS = 20_000
MAX_PENDING_NOTES = 1_000  # ~50 s of reports
# A changed frame goes early no sooner than this after the tick before (Deadlines.early_s).
EARLY_MARGIN_S = 0.002
# The shared state (see the module's docstring).
STATE_HEARTBEAT = struct.Struct("<d")
STATE_LINK = struct.Struct("<IQ")
STATE_SLOTS_AT = 64
STATE_SLOT_BYTES = 16
STATE_SLOTS = 256
STATE_BYTES = STATE_SLOTS_AT + STATE_SLOTS * STATE_SLOT_BYTES


def write_heartbeat(state: mmap.mmap, now_s: float) -> None:
    """The heartbeat at offset 0, packed first and then copied in whole. Never with
    ``Struct.pack_into``: it zero-fills its destination before it converts and packs the
    values, so a reader in another process (the supervisor) can find 0.0 there, a heartbeat
    as old as the machine's uptime, whenever this process is preempted in between."""
    state[0:STATE_HEARTBEAT.size] = STATE_HEARTBEAT.pack(now_s)


def write_link_state(state: mmap.mmap, offset: int, seq: int, timestamp: int) -> None:
    """A link slot's next sequence number and last signing timestamp, copied in whole (as
    :func:`write_heartbeat`: a process killed mid-write leaves no zeros for the server)."""
    state[offset:offset + STATE_LINK.size] = STATE_LINK.pack(seq, timestamp)


class Deadlines:
    """Ticks at t0 + k·period: a late tick does not push later ones back, and a tick later
    than a whole period skips the missed ones instead of bursting them."""

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.t0_s = 0.0
        self.k = 1

    def rephase(self, at_s: float) -> float:
        """Count ticks from ``at_s`` (a send just made); answers the first deadline."""
        self.t0_s = at_s
        self.k = 1
        return self.next_s

    @property
    def next_s(self) -> float:
        return self.t0_s + self.k * self.period_s

    def early_s(self) -> float:
        """The earliest the next tick may go with a changed frame: just after the tick
        before it was due. A change then goes at once unless one already went early since:
        at most one frame per period of the schedule, however often the frame changes. The
        margin keeps two frames apart and the interval after an early frame under two
        periods (which would count as a gap)."""
        return self.next_s - self.period_s + min(EARLY_MARGIN_S, self.period_s / 4.0)

    def after_tick(self, now_s: float) -> float:
        """The deadline after a tick that ran at ``now_s``."""
        self.k += 1
        if self.next_s <= now_s:
            self.k = math.floor((now_s - self.t0_s) / self.period_s) + 1
        return self.next_s


def x25crc(data: bytes | bytearray, crc: int = 0xFFFF) -> int:
    """MAVLink's CRC-16/MCRF4XX."""
    for byte in data:
        tmp = (byte ^ crc) & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = (crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)
    return crc


class Stamper:
    """One link's sequence number and signing state: re-stamps frames packed unsigned."""

    def __init__(self, seq: int, signing: tuple[bytes, int, int] | None) -> None:
        self.seq = seq % 256
        self.key: bytes | None = None
        self.link_id = 0
        self.timestamp = 0
        self.sign(signing)

    def sign(self, signing: tuple[bytes, int, int] | None) -> None:
        if signing is None:
            self.key = None
            return
        self.key, self.link_id, timestamp = signing
        self.timestamp = max(self.timestamp, timestamp)

    def stamp(self, frame: bytes, crc_extra: int) -> bytes:
        """``frame`` (MAVLink 2, unsigned) with the next sequence number, signed with a key."""
        buf = bytearray(frame)
        if not buf or buf[0] != MAVLINK_STX_V2:
            return frame  # only MAVLink 2 frames are re-stamped (the link packs nothing else)
        payload_end = 10 + buf[1]
        buf[4] = self.seq
        self.seq = (self.seq + 1) % 256
        if self.key is not None:
            buf[2] |= MAVLINK_IFLAG_SIGNED
        del buf[payload_end:]
        buf += struct.pack("<H", x25crc(bytes([crc_extra]), x25crc(buf[1:])))
        if self.key is not None:
            # never behind the clock, and rising by at least one per frame
            now_ticks = int((time.time() - SIGNING_EPOCH_UNIX_S) * SIGNING_TICKS_PER_S)
            self.timestamp = max(self.timestamp + 1, now_ticks)
            buf += struct.pack("<BQ", self.link_id, self.timestamp)[:7]
            buf += hashlib.sha256(self.key + buf).digest()[:6]
        return bytes(buf)


class LinkOut:
    """A link's socket and stamper, and what was written since the last report."""

    def __init__(self, sock: socket.socket, stamper: Stamper,
                 state: tuple[mmap.mmap, int] | None = None) -> None:
        self.sock = sock
        self.stamper = stamper
        self.records: list[tuple[float, bytes]] = []
        self.dropped = 0
        self.state = state  # (shared state, offset of this link's slot)

    def write(self, frame: bytes, crc_extra: int, dests: Iterable[Any] | None) -> bool:
        stamped = self.stamper.stamp(frame, crc_extra)
        if self.state is not None:
            write_link_state(self.state[0], self.state[1], self.stamper.seq,
                             self.stamper.timestamp)
        try:
            if dests is None:
                self.sock.send(stamped)
            else:
                sent = False
                for addr in dests:
                    self.sock.sendto(stamped, addr)
                    sent = True
                if not sent:
                    self.dropped += 1
                    return False
        except OSError:  # buffer full (non-blocking) or unreachable: dropped, counted
            self.dropped += 1
            return False
        self.records.append((time.time(), stamped))
        if len(self.records) > MAX_PENDING_RECORDS:
            del self.records[: len(self.records) - MAX_PENDING_RECORDS]
        return True


class Stream:
    def __init__(self, key: int, frame: bytes, crc_extra: int, dests: Any, period_s: float
                 ) -> None:
        self.key = key
        self.frame = frame
        self.crc_extra = crc_extra
        self.dests = dests
        self.deadlines = Deadlines(period_s)
        self.generation = 0
        self.last_s: float | None = None
        self.ticks: list[float] = []


class SenderProcess:
    def __init__(self, control: socket.socket, state: mmap.mmap | None = None) -> None:
        self.control = control
        self.state = state
        self.links: dict[int, LinkOut] = {}
        self.streams: dict[int, Stream] = {}
        self.heap: list[tuple[float, int, int, int]] = []  # (deadline, order, sid, generation)
        self.order = itertools.count()
        self.notes: list[tuple[Any, ...]] = []

    # -- the server's messages --
    def handle(self, message: tuple[Any, ...], fds: list[int]) -> None:
        kind = message[0]
        if kind == "link":
            key, seq, signing = message[1:4]
            slot = message[4] if len(message) > 4 else -1
            old = self.links.pop(key, None)
            if old is not None:
                old.sock.close()
            sock = socket.socket(fileno=fds[0])
            sock.setblocking(False)
            state = None
            if self.state is not None and 0 <= slot < STATE_SLOTS:
                state = (self.state, STATE_SLOTS_AT + slot * STATE_SLOT_BYTES)
            self.links[key] = LinkOut(sock, Stamper(seq, signing), state)
            return
        for fd in fds:  # only "link" carries one
            os.close(fd)
        if kind == "unlink":
            for sid in [s for s, stream in self.streams.items() if stream.key == message[1]]:
                self.end_stream(sid)
            self.flush_link(message[1])
            out = self.links.pop(message[1], None)
            if out is not None:
                out.sock.close()
            self.notes.append(("unlinked", message[1]))
            self.report()
        elif kind == "sign":
            out = self.links.get(message[1])
            if out is not None:
                out.stamper.sign(message[2])
        elif kind == "send":
            _, key, frame, crc_extra, dests = message
            out = self.links.get(key)
            if out is not None:
                out.write(frame, crc_extra, dests)
        elif kind == "stream":
            _, sid, key, frame, crc_extra, dests, period_s = message
            stream = self.streams.get(sid)
            if stream is None or stream.key != key:
                stream = self.streams[sid] = Stream(key, frame, crc_extra, dests, period_s)
            stream.frame, stream.crc_extra, stream.dests = frame, crc_extra, dests
            stream.deadlines.period_s = period_s
            self.tick(sid, stream, time.monotonic(), rephase=True)
        elif kind == "update":
            _, sid, frame, crc_extra, dests = message
            stream = self.streams.get(sid)
            if stream is not None:
                stream.frame, stream.crc_extra, stream.dests = frame, crc_extra, dests
        elif kind == "change":
            _, sid, frame, crc_extra, dests = message
            stream = self.streams.get(sid)
            if stream is not None:
                stream.frame, stream.crc_extra, stream.dests = frame, crc_extra, dests
                now = time.monotonic()
                early_s = stream.deadlines.early_s()
                if now >= early_s:
                    self.tick(sid, stream, now)  # the next tick, now
                else:
                    self.schedule(sid, stream, early_s)
        elif kind == "period":
            _, sid, period_s = message
            stream = self.streams.get(sid)
            if stream is not None:
                stream.deadlines.period_s = period_s
                if stream.last_s is not None:
                    self.schedule(sid, stream, stream.deadlines.rephase(stream.last_s))
        elif kind == "stop":
            self.end_stream(message[1])

    def end_stream(self, sid: int) -> None:
        stream = self.streams.pop(sid, None)
        if stream is not None and stream.ticks:
            self.notes.append(("ticks", sid, stream.ticks))

    # -- the streams --
    def schedule(self, sid: int, stream: Stream, deadline_s: float) -> None:
        stream.generation += 1
        heapq.heappush(self.heap, (deadline_s, next(self.order), sid, stream.generation))

    def tick(self, sid: int, stream: Stream, now_s: float, *, rephase: bool = False) -> None:
        out = self.links.get(stream.key)
        if out is None:
            self.end_stream(sid)
            return
        out.write(stream.frame, stream.crc_extra, stream.dests)
        stream.ticks.append(now_s)
        stream.last_s = now_s
        if rephase:
            self.schedule(sid, stream, stream.deadlines.rephase(now_s))
        else:
            self.schedule(sid, stream, stream.deadlines.after_tick(now_s))

    def run_due(self) -> None:
        while self.heap and self.heap[0][0] <= time.monotonic():
            _, _, sid, generation = heapq.heappop(self.heap)
            stream = self.streams.get(sid)
            if stream is not None and stream.generation == generation:
                self.tick(sid, stream, time.monotonic())

    # -- reports --
    def flush_link(self, key: int) -> None:
        out = self.links.get(key)
        if out is not None and (out.records or out.dropped):
            self.notes.append(("sent", key, out.records, out.dropped, out.stamper.timestamp))
            out.records, out.dropped = [], 0

    def report(self) -> None:
        for key in self.links:
            self.flush_link(key)
        for sid, stream in self.streams.items():
            if stream.ticks:
                self.notes.append(("ticks", sid, stream.ticks))
                stream.ticks = []
        if len(self.notes) > MAX_PENDING_NOTES:  # a server that stopped reading
            del self.notes[: len(self.notes) - MAX_PENDING_NOTES]
        while self.notes:
            try:
                self.control.send(pickle.dumps(self.notes[0], pickle.HIGHEST_PROTOCOL))
            except BlockingIOError:
                return  # the server reads later; the notes wait
            except OSError as exc:
                if exc.errno == errno.EMSGSIZE:
                    self.notes.pop(0)  # too large for one message (cannot happen in 50 ms)
                    continue
                raise
            self.notes.pop(0)

    def read_control(self) -> bool:
        """Take every waiting message; False at end of file (the server is gone)."""
        while True:
            try:
                data, fds, _flags, _addr = socket.recv_fds(
                    self.control, MAX_CONTROL_MESSAGE_BYTES, 4)
            except BlockingIOError:
                return True
            if not data:
                return False
            self.handle(pickle.loads(data), fds)
            self.run_due()  # a burst of the server's frames does not hold a due tick back

    def run(self) -> None:
        next_report_s = time.monotonic()  # the first report ("ready") goes at once
        poller = select.poll()  # not select(): the control socket's fd may be above 1023
        poller.register(self.control, select.POLLIN)
        while True:
            now = time.monotonic()
            if self.state is not None:
                write_heartbeat(self.state, now)
            until = min(next_report_s, self.heap[0][0] if self.heap else math.inf)
            wait_s = max(0.0, until - now)
            if wait_s < 0.001:  # poll counts whole milliseconds: the rest is slept
                time.sleep(wait_s)
                wait_s = 0.0
            readable = poller.poll(int(wait_s * 1000.0))  # early by < 1 ms: comes round
            self.run_due()
            if readable and not self.read_control():
                return
            if time.monotonic() >= next_report_s:
                self.report()
                next_report_s = time.monotonic() + REPORT_PERIOD_S


def _die_with_parent(parent_pid: int) -> None:
    """SIGKILL this process when the server dies (Linux), even if the control socket's
    other end stayed open somewhere."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent_pid:  # it died before the request took effect
        os._exit(0)


def _raise_priority(priority: int) -> str | None:
    """SCHED_FIFO at ``priority`` for this process; the reason why not, if it cannot."""
    if priority <= 0:
        return None
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return (f"setpoint sender process runs at normal priority: real-time scheduling "
                f"(SCHED_FIFO {priority}) refused ({exc}); allow it for steady setpoints on "
                f"a busy machine: CAP_SYS_NICE (docker: --cap-add SYS_NICE) or an rtprio "
                f"limit of {priority} (docker: --ulimit rtprio={priority}); see docs/link.md")
    return None


def main() -> None:
    parent_pid, priority, control_fd = (int(arg) for arg in sys.argv[1:4])
    _die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C stops the server, then us
    control = socket.socket(fileno=control_fd)
    control.setblocking(False)
    state = None
    if len(sys.argv) > 4:
        state_fd = int(sys.argv[4])
        state = mmap.mmap(state_fd, STATE_BYTES)
        os.close(state_fd)
    process = SenderProcess(control, state)
    process.notes.append(("ready", os.getpid()))
    warning = _raise_priority(priority)
    if warning is not None:
        process.notes.append(("warning", warning))
    with contextlib.suppress(BrokenPipeError, ConnectionResetError):
        process.run()  # those two: the server closed its end while we reported


if __name__ == "__main__":
    main()
