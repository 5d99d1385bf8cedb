"""The setpoint sender process fails mid-stream (kill -9, SIGSTOP, a control channel it
stops reading, descriptors above 1023): the stream goes on from the sender thread with no
gap a vehicle can feel, the sequence stays contiguous and signed frames pass a replay check,
a restarted process takes the stream back, and the figures say what happened. Times are the
kernel's receive times at a UDP receiver (a busy test process does not move them)."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import mmap
import os
import re
import resource
import secrets
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.signing_keys import SigningKeyStore
from server.link.link import Link
from server.link.stream import stream_channel, stream_process, stream_thread
from server.link.stream.sender_supervisor import ProcessGone, SenderSupervisor
from server.link.stream.streamer import SetpointStreamer
from tests.link.test_stream_process import Receiver
from tests.waiting import wait_for, wait_for_blocking

MAV = mavlink.MAVLink(None)
RATE_HZ = 20.0
# the largest gap a vehicle may see when the sender dies, and when it stops answering
KILL_GAP_S = 0.150
STOP_GAP_S = 0.250
SETPOINT_ID = mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED


def _msg(x: float) -> mavlink.MAVLink_message:
    return MAV.set_position_target_local_ned_encode(
        0, 1, 1, 1, 2552, x, 0, -5, 0, 0, 0, 0, 0, 0, 0, 0
    )


class Flight:
    """A link streaming setpoints at RATE_HZ to a receiver, and what it heard."""

    def __init__(self, link: Link, receiver: Receiver, key: bytes | None) -> None:
        self.link = link
        self.receiver = receiver
        self.key = key
        self.streamer = SetpointStreamer(link.send, rate_hz=RATE_HZ, channel=link.stream_channel)
        self.changes: list[dict[str, Any]] = []
        self.streamer.on_sender_change = self.changes.append

    def decoded(self) -> list[tuple[float, mavlink.MAVLink_message]]:
        """Every frame received, checked as a vehicle would (signature, replay)."""
        checker = mavlink.MAVLink(None)
        if self.key is not None:
            checker.signing.secret_key = self.key
            checker.signing.sign_outgoing = False
        out = []
        for t, frame in self.receiver.frames:
            msgs = checker.parse_buffer(frame)
            assert msgs is not None
            assert len(msgs) == 1
            assert msgs[0].get_type() != "BAD_DATA", "a frame the vehicle would reject"
            out.append((t, msgs[0]))
        if self.key is not None:
            assert checker.signing.badsig_count == 0
        return out


async def _flight(tmp_path: Path, signed: bool) -> tuple[Flight, Receiver]:
    receiver = Receiver()
    key = None
    store = None
    if signed:
        key = secrets.token_bytes(32)
        store = SigningKeyStore(tmp_path / "signing.key")
        store.replace_key(key)
    link = await Link.open(f"udpout:127.0.0.1:{receiver.port}", signing_store=store)
    return Flight(link, receiver, key), receiver


def _check_wire(flight: Flight, gap_bound_s: float) -> float:
    """The setpoints' largest gap at the receiver (asserted ≤ ``gap_bound_s``), after
    checking every frame: sequence contiguous, signed and never replayed."""
    decoded = flight.decoded()
    seqs = [m.get_seq() for _, m in decoded]
    jumps = [(a, b) for a, b in itertools.pairwise(seqs) if (b - a) % 256 != 1]
    assert jumps == [], f"the sequence jumps: {jumps[:5]}"
    if flight.key is not None:
        assert all(m._signed for _, m in decoded)
    times = [t for t, m in decoded if m.get_msgId() == SETPOINT_ID]
    largest = max(b - a for a, b in itertools.pairwise(times))
    print(f"largest setpoint gap at the receiver: {largest * 1000:.1f} ms")
    assert largest <= gap_bound_s, f"a {largest * 1000:.0f} ms gap at the vehicle"
    return largest


async def _stream_through(flight: Flight, fault: Any, after_s: float) -> None:
    streamer = flight.streamer
    streamer.stream(_msg(1))
    assert streamer.in_process
    await asyncio.sleep(0.5)
    await fault()
    await asyncio.sleep(after_s)


async def test_the_thread_that_takes_over_runs_at_its_priority_before_the_process_is_lost(
    tmp_path: Path, supervisor: SenderSupervisor, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Started at the loss, the thread would first wait for a core as an ordinary thread
    (tens of milliseconds beside busy cores, seen as a gap at the vehicle) before it raised
    its priority."""
    monkeypatch.setattr(stream_thread, "_shared", None)  # a sender thread of this test's own
    flight, receiver = await _flight(tmp_path, signed=False)
    try:
        assert stream_thread.shared_sender().native_id is None
        flight.streamer.stream(_msg(1))
        assert flight.streamer.in_process
        sender = stream_thread.shared_sender()
        tid = sender.native_id
        assert tid is not None, "no sender thread while the process streams"
        assert sender.pending() == 0  # idle: the process sends
        if stream_thread.SENDER_RT_PRIORITY > 0:
            await wait_for(lambda: os.sched_getscheduler(tid) & 0xFF == os.SCHED_FIFO, 1.0,
                           "the idle thread at real-time priority")
            assert os.sched_getparam(tid).sched_priority == stream_thread.SENDER_RT_PRIORITY
        flight.streamer.stop()
    finally:
        await flight.link.close()
        receiver.close()


@pytest.mark.parametrize("signed", [False, True], ids=["unsigned", "signed"])
async def test_kill_9_of_the_sender_the_thread_takes_over_and_a_new_process_takes_back(
    tmp_path: Path, supervisor: SenderSupervisor, signed: bool
) -> None:
    flight, receiver = await _flight(tmp_path, signed)
    streamer = flight.streamer
    seen: list[dict[str, Any]] = []
    try:
        async def kill() -> None:
            process = supervisor.current()
            assert process is not None
            assert process.pid is not None
            os.kill(process.pid, signal.SIGKILL)
            await wait_for(lambda: streamer.sender == "thread", 1.0, "the thread takes over")
            stats = streamer.stats()
            seen.append({"sender": stats.sender, "active": stats.active,
                         "fault": stats.sender_fault})
            streamer.update(_msg(2))  # a new setpoint reaches the vehicle from the thread

        await _stream_through(flight, kill, 0.3)
        await wait_for(lambda: streamer.sender == "process", 3.0, "a new process takes over")
        streamer.update(_msg(3))
        await asyncio.sleep(0.5)
        stats = streamer.stats()
        streamer.stop()
    finally:
        await flight.link.close()
    await wait_for(lambda: len(receiver.frames) >= flight.link.stats().frames_out, 5.0,
                   "every frame at the receiver")
    receiver.close()
    assert seen[0]["sender"] == "thread"
    assert seen[0]["active"]
    assert "SIGKILL" in seen[0]["fault"]
    assert stats.sender == "process"
    assert stats.sender_restarts == 1
    assert stats.active
    _check_wire(flight, KILL_GAP_S)
    xs = [m.x for _, m in flight.decoded() if m.get_msgId() == SETPOINT_ID]
    assert xs[0] == 1.0
    assert 2.0 in xs
    assert xs[-1] == 3.0
    await asyncio.sleep(0)  # the loop delivers the changes
    assert [c.get("sender") for c in flight.changes] == ["thread", "process"]


async def test_a_stopped_sender_is_killed_and_the_thread_takes_over(
    tmp_path: Path, supervisor: SenderSupervisor
) -> None:
    flight, receiver = await _flight(tmp_path, signed=True)
    streamer = flight.streamer
    try:
        async def stop() -> None:
            process = supervisor.current()
            assert process is not None
            assert process.pid is not None
            os.kill(process.pid, signal.SIGSTOP)
            # new setpoints while it is stopped: latest wins, the loop never waits
            for i in range(2000):
                streamer.update(_msg(10 + i))
            assert isinstance(process, stream_channel.SenderProcess)
            assert len(process._outbox) <= 1  # one stream: one queued message at most
            await asyncio.sleep(3.0)
            with contextlib.suppress(ProcessLookupError):
                os.kill(process.pid, signal.SIGCONT)

        await _stream_through(flight, stop, 0.5)
        stats = streamer.stats()
        streamer.stop()
    finally:
        await flight.link.close()
    await wait_for(lambda: len(receiver.frames) >= flight.link.stats().frames_out, 5.0,
                   "every frame at the receiver")
    receiver.close()
    assert stats.sender_fault is not None
    assert "stopped answering" in stats.sender_fault
    # a stopped process neither ran nor waited for a CPU: the fault says it was not starved
    ran = re.search(r"it ran (\d+) ms and waited (\d+) ms for a CPU", stats.sender_fault)
    assert ran is not None, stats.sender_fault
    assert int(ran[1]) <= 5, stats.sender_fault
    assert int(ran[2]) <= 5, stats.sender_fault
    assert supervisor.faults == 1
    _check_wire(flight, STOP_GAP_S)
    xs = [m.x for _, m in flight.decoded() if m.get_msgId() == SETPOINT_ID]
    assert xs[-1] == 10.0 + 1999  # the newest setpoint, whoever sent it


def test_a_full_control_channel_is_a_fault_not_a_blocked_caller(
    supervisor: SenderSupervisor,
) -> None:
    process = supervisor.process()
    assert isinstance(process, stream_channel.SenderProcess)
    assert process.pid is not None
    os.kill(process.pid, signal.SIGSTOP)
    failure: ProcessGone | None = None
    try:
        for _ in range(100_000):  # each distinct: none replaces another
            try:
                process.post(("send", 1, b"x" * 200, 0, None))
            except ProcessGone as exc:
                failure = exc
                break
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(process.pid, signal.SIGCONT)
    assert failure is not None, "the channel never filled"
    assert "control channel is full" in str(failure)
    assert len(process._outbox) <= stream_channel.MAX_OUTBOX
    until = time.monotonic() + 5.0
    while supervisor.last_fault is None and time.monotonic() < until:
        time.sleep(0.01)
    assert supervisor.last_fault is not None
    assert "control channel is full" in supervisor.last_fault  # killed for it, and said so


def test_a_writer_thread_kept_waiting_does_not_fill_the_outbox(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The server's writer thread may wait long for its turn on a busy machine: the callers
    write what waits themselves, so the outbox holds only what the process has not read."""
    monkeypatch.setattr(stream_channel.SenderProcess, "_write_outbox", lambda self: None)
    process = stream_channel.SenderProcess()
    try:
        assert process.wait_ready(5.0)
        assert process.pid is not None
        os.kill(process.pid, signal.SIGSTOP)  # a moment without reading: some wait...
        for _ in range(10_000):
            process.post(("send", 1, b"x" * 200, 0, None))  # no such link: read, ignored
            if process._outbox:
                break
        os.kill(process.pid, signal.SIGCONT)  # ... and it reads again
        for i in range(3 * stream_channel.MAX_OUTBOX):
            process.post(("send", 1, b"x" * 200, 0, None))
            if i % 8 == 0:
                time.sleep(0.001)  # the process reads at its pace
        assert process.alive
        assert process.fault is None
    finally:
        process.kill("the test ends")
        assert process.wait_ended(5.0)


def test_frames_left_in_the_outbox_of_a_lost_process_are_counted_dropped() -> None:
    process = stream_channel.SenderProcess()
    dropped: list[int] = []
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        assert process.wait_ready(5.0)
        process.attach(7, sock, 0, None, lambda records, n, _ts: dropped.append(n))
        assert process.pid is not None
        os.kill(process.pid, signal.SIGSTOP)
        for _ in range(10_000):  # until the control socket holds no more: some wait
            process.post(("send", 7, b"x" * 200, 0, [("127.0.0.1", 9)]))
            if len(process._outbox) >= 5:
                break
        waiting = len(process._outbox)
        assert waiting > 0
        process.kill("the test stops it")
        with contextlib.suppress(ProcessLookupError):
            os.kill(process.pid, signal.SIGCONT)
        wait_for_blocking("the loss", lambda: sum(dropped) >= waiting, 5.0, 0.01)
        assert sum(dropped) == waiting
    finally:
        sock.close()


async def test_streams_work_above_descriptor_1023(
    tmp_path: Path, supervisor: SenderSupervisor
) -> None:
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard != resource.RLIM_INFINITY and hard < 2048:
        pytest.skip(f"the descriptor limit is {hard}")
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, 4096), hard))
    idle = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(1100)]
    try:
        assert max(s.fileno() for s in idle) > 1024
        flight, receiver = await _flight(tmp_path, signed=False)
        try:
            flight.streamer.stream(_msg(1))
            assert flight.streamer.in_process
            await asyncio.sleep(1.0)
            stats = flight.streamer.stats()
            flight.streamer.stop()
        finally:
            await flight.link.close()
        receiver.close()
    finally:
        for s in idle:
            s.close()
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
    assert supervisor.faults == 0, supervisor.last_fault
    assert stats.sender == "process"
    assert stats.active
    assert stats.sent >= 15
    _check_wire(flight, KILL_GAP_S)


class _Probe:
    """A value that, when a writer converts it, reads what the page holds at that moment:
    between the writer's first touch of the page and its last."""

    def __init__(self, page: mmap.mmap, value: float, read: Callable[[mmap.mmap], Any]) -> None:
        self._page, self._value, self._read = page, value, read
        self.seen: list[Any] = []

    def __float__(self) -> float:
        self.seen.append(self._read(self._page))
        return self._value

    def __index__(self) -> int:
        self.seen.append(self._read(self._page))
        return int(self._value)


def test_the_state_page_never_holds_zeros_while_it_is_written() -> None:
    """A live sender was once killed as silent for "no heartbeat for 5109734 ms" (the
    machine's uptime): the supervisor read 0.0 while the process was between zero-filling
    its heartbeat and writing it (``Struct.pack_into`` does both, with the value converted
    in between). A reader at that moment sees the previous heartbeat and link slot."""
    fd = os.memfd_create("skyhelm-test-state", os.MFD_CLOEXEC)
    try:
        os.ftruncate(fd, stream_process.STATE_BYTES)
        page = mmap.mmap(fd, stream_process.STATE_BYTES)
    finally:
        os.close(fd)
    slot_at = stream_process.STATE_SLOTS_AT + 3 * stream_process.STATE_SLOT_BYTES
    stream_process.write_heartbeat(page, 1000.0)
    stream_process.write_link_state(page, slot_at, 41, 7_000_000)

    beat = _Probe(page, 1000.05,
                  lambda p: stream_process.STATE_HEARTBEAT.unpack_from(p, 0)[0])
    stream_process.write_heartbeat(page, cast(float, beat))
    assert beat.seen == [1000.0]
    assert stream_process.STATE_HEARTBEAT.unpack_from(page, 0) == (1000.05,)

    seq = _Probe(page, 42, lambda p: stream_process.STATE_LINK.unpack_from(p, slot_at))
    stream_process.write_link_state(page, slot_at, cast(int, seq), 7_000_001)
    assert seq.seen == [(41, 7_000_000)]
    assert stream_process.STATE_LINK.unpack_from(page, slot_at) == (42, 7_000_001)
    assert stream_process.STATE_HEARTBEAT.unpack_from(page, 0) == (1000.05,)  # untouched


def test_a_start_slower_than_its_timeout_leaves_no_process_and_no_closed_descriptor(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """On a slow machine the fork may come after the server stopped waiting: the
    descriptors it passes are still open then (closed once the fork is done, not at the
    timeout), and the late process, which nobody owns, is killed."""
    real_popen = subprocess.Popen
    started: list[subprocess.Popen[bytes]] = []
    errors: list[OSError] = []
    done = threading.Event()

    def slow_popen(*args: Any, **kwargs: Any) -> subprocess.Popen[bytes]:
        time.sleep(0.3)  # the fork comes after the timeout
        try:
            proc = real_popen(*args, **kwargs)
        except OSError as exc:
            errors.append(exc)
            raise
        finally:
            done.set()
        started.append(proc)
        return proc

    monkeypatch.setattr(stream_channel, "START_TIMEOUT_S", 0.05)
    monkeypatch.setattr(stream_channel.subprocess, "Popen", slow_popen)
    with pytest.raises(ProcessGone, match=r"not started in 0\.05 s"):
        stream_channel.SenderProcess()
    assert done.wait(5.0)
    assert errors == [], "the descriptors passed were closed before the fork"
    assert len(started) == 1
    assert started[0].wait(5.0) == -signal.SIGKILL  # killed: nobody owns it


class _ReadThenWait:
    """The heartbeat's layout, whose reader is kept waiting after it read (a thread of a
    busy server that loses its turn between two lines)."""

    def __init__(self, wait_s: float) -> None:
        self.wait_s = wait_s
        self.layout = stream_process.STATE_HEARTBEAT

    def unpack_from(self, page: Any, offset: int) -> tuple[float]:
        beat = cast(tuple[float], self.layout.unpack_from(page, offset))
        time.sleep(self.wait_s)
        return beat


def test_a_reader_kept_waiting_does_not_age_the_heartbeat(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    process = stream_channel.SenderProcess()
    try:
        assert process.wait_ready(5.0)
        monkeypatch.setattr(stream_channel.stream_process, "STATE_HEARTBEAT",
                            _ReadThenWait(0.3), raising=True)
        age_s = process.heartbeat_age_s()
        monkeypatch.undo()
        assert age_s is not None
        assert age_s < 0.15  # the process went round every report period meanwhile
    finally:
        process.kill("the test ends")
        assert process.wait_ended(5.0)
