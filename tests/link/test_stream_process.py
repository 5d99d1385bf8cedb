"""The setpoint sender process: it writes every frame of a UDP link once a stream put the
link there (sequence contiguous, signed, recorded), the newest setpoint wins, its ticks
come back as the stream's figures, and it dies with the server."""

from __future__ import annotations

import asyncio
import hashlib
import itertools
import os
import pickle
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import development as mavlink

from bench._receiver import SO_TIMESTAMPNS, kernel_receive_time
from server.link.codec.signing_keys import SigningKeyStore
from server.link.codec.tlog import iter_tlog
from server.link.link import Link
from server.link.stream import stream_process
from server.link.stream.streamer import SetpointStreamer
from tests.waiting import wait_for

MAV = mavlink.MAVLink(None)
PROJECT_ROOT = Path(__file__).resolve().parents[2]


def _msg(x: float) -> mavlink.MAVLink_message:
    return MAV.set_position_target_local_ned_encode(
        0, 1, 1, 1, 2552, x, 0, -5, 0, 0, 0, 0, 0, 0, 0, 0
    )


# After the server died, no setpoint may reach the vehicle later than this.
DEATH_BOUND_S = 0.5


class Receiver:
    """A UDP socket read by a thread: every datagram with the kernel's receive time (Unix
    seconds), so a busy test process does not move the times."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
        self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.1)
        self.frames: list[tuple[float, bytes]] = []
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return int(self.sock.getsockname()[1])

    def _read(self) -> None:
        while not self._done.is_set():
            try:
                data, ancillary, _flags, _addr = self.sock.recvmsg(2048, 64)
            except TimeoutError:
                continue
            self.frames.append((kernel_receive_time(ancillary), data))

    def close(self) -> None:
        self._done.set()
        self._thread.join(5.0)
        self.sock.close()


async def test_every_frame_goes_through_the_process_contiguous_signed_and_recorded(
    tmp_path: Path,
) -> None:
    key = secrets.token_bytes(32)
    store = SigningKeyStore(tmp_path / "signing.key")
    store.replace_key(key)
    receiver = Receiver()
    per_sender = 1000
    link = await Link.open(f"udpout:127.0.0.1:{receiver.port}", log_dir=tmp_path / "logs",
                           signing_store=store)
    try:
        streamer = SetpointStreamer(link.send, rate_hz=100, channel=link.stream_channel)
        streamer.stream(_msg(1))
        assert streamer.in_process
        for i in range(per_sender):
            link.send(MAV.param_request_read_encode(1, 1, b"P", i))
            if i % 20 == 0:
                await asyncio.sleep(0.002)
        streamer.update(_msg(2))  # the next ticks send this: latest wins
        await asyncio.sleep(0.3)
        stats = streamer.stats()
        streamer.stop()
        tlog_path = link.tlog_path
    finally:
        await link.close()  # waits for the process's last report
    sent = link.stats().frames_out
    await wait_for(lambda: len(receiver.frames) >= sent, 10.0, "every frame at the receiver")
    receiver.close()

    checker = mavlink.MAVLink(None)
    checker.signing.secret_key = key
    checker.signing.sign_outgoing = False
    decoded = []
    for _, frame in receiver.frames:
        msgs = checker.parse_buffer(frame)  # a bad or replayed signature: BAD_DATA
        assert msgs is not None
        assert len(msgs) == 1
        decoded.append(msgs[0])
    assert [m for m in decoded if m.get_type() == "BAD_DATA"] == []
    assert all(m._signed for m in decoded)
    assert checker.signing.badsig_count == 0
    assert len(decoded) == sent
    seqs = [m.get_seq() for m in decoded]
    assert all((b - a) % 256 == 1 for a, b in itertools.pairwise(seqs)), \
        "sequence numbers skip or repeat"
    setpoints = [m for m in decoded if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    assert [m.get_type() for m in decoded].count("PARAM_REQUEST_READ") == per_sender
    assert setpoints[-1].x == 2.0
    assert setpoints[0].x == 1.0
    # the stream's figures are the process's tick times
    assert stats.sent >= 20
    assert 80 <= stats.rate_hz <= 120
    assert tlog_path is not None
    assert sorted(frame for _, frame in iter_tlog(tlog_path)) == sorted(
        frame for _, frame in receiver.frames)


def _signed_with(key: bytes, frame: bytes) -> bool:
    """Whether a signed MAVLink 2 frame's signature is the one ``key`` makes."""
    return hashlib.sha256(key + frame[:-6]).digest()[:6] == frame[-6:]


async def test_a_key_change_reaches_the_process_in_order_with_the_frames(tmp_path: Path) -> None:
    old_key, new_key = secrets.token_bytes(32), secrets.token_bytes(32)
    store = SigningKeyStore(tmp_path / "signing.key")
    store.replace_key(old_key)
    receiver = Receiver()
    link = await Link.open(f"udpout:127.0.0.1:{receiver.port}", signing_store=store)
    try:
        streamer = SetpointStreamer(link.send, rate_hz=50, channel=link.stream_channel)
        streamer.stream(_msg(1))
        await asyncio.sleep(0.2)
        link.send(MAV.param_request_read_encode(1, 1, b"BEFORE", -1))
        link.signing.use_key(new_key, link.signing.state.timestamp)
        link.send(MAV.param_request_read_encode(1, 1, b"AFTER", -1))
        await asyncio.sleep(0.2)
        streamer.stop()
    finally:
        await link.close()
    await wait_for(lambda: len(receiver.frames) >= link.stats().frames_out, 10.0,
                   "every frame at the receiver")
    receiver.close()
    frames = [frame for _, frame in receiver.frames]
    marks = [i for i, f in enumerate(frames) if b"BEFORE" in f or b"AFTER" in f]
    assert len(marks) == 2
    assert all(_signed_with(old_key, f) for f in frames[: marks[0] + 1])
    assert all(_signed_with(new_key, f) for f in frames[marks[1]:])
    assert len(frames) - marks[1] >= 5  # the stream went on, signed with the new key


def _xs(frames: list[tuple[float, bytes]]) -> list[tuple[float, float]]:
    """(kernel receive time, x) of each setpoint frame."""
    out = []
    for arrived, frame in frames:
        msg = mavlink.MAVLink(None).parse_char(frame)
        if msg is not None and msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            out.append((arrived, msg.x))
    return out


async def test_a_change_reaches_the_vehicle_before_the_next_tick_was_due() -> None:
    """A pilot's changed input goes out of the process when it comes, in place of the next
    tick; the ticks after it keep their times. Times are the kernel's receive times at the
    vehicle's socket, against the stream's own schedule (its first frame's arrival)."""
    period_s = 0.5
    receiver = Receiver()
    link = await Link.open(f"udpout:127.0.0.1:{receiver.port}")
    try:
        streamer = SetpointStreamer(link.send, rate_hz=1.0 / period_s,
                                    channel=link.stream_channel)
        streamer.stream(_msg(1))
        assert streamer.in_process
        await wait_for(lambda: bool(_xs(receiver.frames)), 5.0, "the first setpoint")
        first_s = _xs(receiver.frames)[0][0]
        # give the change well inside a period (a busy test process tries the next one)
        while True:
            into_s = (time.time() - first_s) % period_s
            if 0.1 <= into_s <= 0.3:
                break
            await asyncio.sleep(0.02)
        changed_s = time.time()
        streamer.change(_msg(2))
        next_due_s = changed_s - into_s + period_s
        await wait_for(lambda: any(x == 2 for _, x in _xs(receiver.frames)), 5.0,
                       "the changed setpoint")
        await asyncio.sleep(next_due_s + period_s + 0.2 - time.time())
        streamer.stop()
    finally:
        await link.close()
    receiver.close()
    heard = _xs(receiver.frames)
    changed = [t for t, x in heard if x == 2]
    assert changed[0] < next_due_s - 0.05, (
        f"the change came {changed[0] - changed_s:.3f} s after it was given, "
        f"{changed[0] - next_due_s:.3f} s after the next tick was due")
    # it took the place of that tick: the next frame is the one after, on its time
    after = changed[1]
    assert after >= next_due_s + period_s - 0.05
    assert [t for t, _ in heard if changed[0] < t < after] == []


async def test_changes_faster_than_the_stream_do_not_raise_its_rate() -> None:
    """Sticks changing at ~100 Hz on a 10 Hz stream in the process: never more frames
    than one a period (and one early) at the vehicle's socket."""
    period_s = 0.1
    receiver = Receiver()
    link = await Link.open(f"udpout:127.0.0.1:{receiver.port}")
    try:
        streamer = SetpointStreamer(link.send, rate_hz=1.0 / period_s,
                                    channel=link.stream_channel)
        streamer.stream(_msg(0))
        assert streamer.in_process
        await wait_for(lambda: bool(_xs(receiver.frames)), 5.0, "the first setpoint")
        begin_s = time.time()
        for k in range(1, 101):
            streamer.change(_msg(k))
            await asyncio.sleep(0.01)
        end_s = time.time()
        await wait_for(lambda: any(x == 100 for _, x in _xs(receiver.frames)), 5.0,
                       "the last change")
        streamer.stop()
    finally:
        await link.close()
    receiver.close()
    heard = [(t, x) for t, x in _xs(receiver.frames) if x >= 1]
    within = [t for t, _ in heard if t <= end_s]
    assert len(within) <= (end_s - begin_s) / period_s + 2, (
        f"{len(within)} frames in {end_s - begin_s:.2f} s of a {1 / period_s:g} Hz stream")
    assert len({x for _, x in heard}) >= 5  # and the changes went out, the newest each time


async def test_a_link_without_a_socket_to_hand_over_streams_on_the_thread() -> None:
    async with await Link.open("tcpin:127.0.0.1:0") as link:
        streamer = SetpointStreamer(link.send, rate_hz=50, channel=link.stream_channel)
        streamer.stream(_msg(1))
        try:
            assert not streamer.in_process
            assert streamer.threaded
        finally:
            streamer.stop()


_CHILD = """
import asyncio, sys
from bench._receiver import SO_TIMESTAMPNS, kernel_receive_time
from server.link.link import Link
from server.link.stream.streamer import SetpointStreamer
from server.link.stream import stream_channel
from pymavlink.dialects.v20 import development as mavlink

async def main():
    link = await Link.open(f"udpout:127.0.0.1:{sys.argv[1]}")
    mav = mavlink.MAVLink(None)
    streamer = SetpointStreamer(link.send, rate_hz=50, channel=link.stream_channel)
    streamer.stream(mav.set_position_target_local_ned_encode(
        0, 1, 1, 1, 2552, 0, 0, -5, 0, 0, 0, 0, 0, 0, 0, 0))
    print(stream_channel.shared_process().pid, flush=True)
    await asyncio.sleep(60)

asyncio.run(main())
"""


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM])
def test_the_process_stops_sending_when_the_server_dies(how: signal.Signals) -> None:
    receiver = Receiver()
    server = subprocess.Popen([sys.executable, "-c", _CHILD, str(receiver.port)],
                              stdout=subprocess.PIPE, cwd=PROJECT_ROOT)
    try:
        assert server.stdout is not None
        sender_pid = int(server.stdout.readline())
        wait_for_frames = time.monotonic() + 10
        while len(receiver.frames) < 20 and time.monotonic() < wait_for_frames:
            time.sleep(0.05)
        assert len(receiver.frames) >= 20, "the process never streamed"
        killed_s = time.time()
        server.send_signal(how)
        server.wait(10)
        time.sleep(1.0)
    finally:
        if server.poll() is None:
            server.kill()
        receiver.close()
    after = [t for t, _ in receiver.frames if t > killed_s + DEATH_BOUND_S]
    assert after == [], f"{len(after)} frames more than {DEATH_BOUND_S} s after the kill"
    assert not _running(sender_pid), "the sender process outlived the server"


def _running(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie nobody reaped, as PID 1 of a container may leave
    it, has ended)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "State:\tZ" not in status


@pytest.mark.skipif(shutil.which("setpriv") is None, reason="needs util-linux's setpriv")
def test_without_cap_sys_nice_the_process_warns_once_and_streams_anyway() -> None:
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    receiver = Receiver()
    # the process as a container without CAP_SYS_NICE would run it
    proc = subprocess.Popen(
        ["setpriv", "--bounding-set", "-sys_nice", "--inh-caps", "-sys_nice",
         sys.executable, "-S", str(stream_process.__file__), str(os.getpid()), "30",
         str(theirs.fileno())], pass_fds=(theirs.fileno(),))
    theirs.close()
    try:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.connect(("127.0.0.1", receiver.port))
        frame = bytes(_msg(1).pack(mavlink.MAVLink(None, srcSystem=255, srcComponent=190)))
        socket.send_fds(ours, [pickle.dumps(("link", 1, 0, None))], [sock.fileno()])
        ours.send(pickle.dumps(("stream", 7, 1, frame, _msg(1).crc_extra, None, 0.02)))
        ours.settimeout(5.0)
        notes = [pickle.loads(ours.recv(1 << 20)) for _ in range(4)]  # ready, warning, sent, ticks
        warnings = [note[1] for note in notes if note[0] == "warning"]
        assert len(warnings) == 1
        assert "normal priority" in warnings[0]
        assert "--cap-add SYS_NICE" in warnings[0]
        assert "--ulimit rtprio=30" in warnings[0]
        assert notes[0][0] == "ready"
        assert any(note[0] == "ticks" and note[1] == 7 for note in notes)
        until = time.monotonic() + 5.0
        while len(receiver.frames) < 3 and time.monotonic() < until:
            time.sleep(0.02)
    finally:
        ours.close()  # end of file: the process ends
        proc.wait(5)
        receiver.close()
    assert len(receiver.frames) >= 3
