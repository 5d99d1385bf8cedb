"""The setpoint sender thread: deadline math, its scheduler on a fake clock, the streamer
timed by it, and Link.send shared by the loop and other threads (sequence, signing, tlog).

The scheduler and streamer tests run the thread's body (run_due) on a fake clock, so times
are exact; two tests use the real thread: one shows a busy loop cannot hold the stream up,
the other that concurrent sends stay contiguous and verifiable at a real UDP receiver.
"""

from __future__ import annotations

import asyncio
import itertools
import os
import secrets
import socket
import threading
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.signing_keys import SigningKeyStore
from server.link.codec.tlog import iter_tlog
from server.link.link import Link
from server.link.stream.stream_thread import Deadlines, SenderThread
from server.link.stream.streamer import SetpointStreamer
from tests.link.realtime import may_run_real_time
from tests.waiting import wait_for

MAV = mavlink.MAVLink(None)


def _msg(x: float) -> mavlink.MAVLink_message:
    return MAV.set_position_target_local_ned_encode(
        0, 1, 1, 1, 2552, x, 0, -5, 0, 0, 0, 0, 0, 0, 0, 0
    )


class FakeClock:
    def __init__(self) -> None:
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s


# -- deadline math --

def test_deadlines_fall_on_t0_plus_k_periods_whatever_the_tick_lateness() -> None:
    d = Deadlines(0.02)
    assert d.rephase(10.0) == pytest.approx(10.02)
    # a tick 5 ms late does not move the next deadline
    assert d.after_tick(10.025) == pytest.approx(10.04)
    assert d.after_tick(10.04) == pytest.approx(10.06)


def test_deadlines_skip_the_ticks_missed_by_a_tick_later_than_a_period() -> None:
    d = Deadlines(0.02)
    d.rephase(10.0)
    # the tick due at 10.02 runs at 10.071: 10.04 and 10.06 are past, 10.08 is next
    assert d.after_tick(10.071) == pytest.approx(10.08)
    assert d.k == 4
    assert d.after_tick(10.125) == pytest.approx(10.14)


def test_rephasing_counts_from_the_new_origin_and_a_period_change_applies() -> None:
    d = Deadlines(0.5)
    d.rephase(1.0)
    d.after_tick(1.5)
    d.period_s = 0.1
    assert d.rephase(1.73) == pytest.approx(1.83)


# -- the scheduler on a fake clock --

def test_scheduler_runs_due_jobs_in_deadline_order_and_drops_finished_and_failed_ones() -> None:
    clock = FakeClock()
    sender = SenderThread(clock, threaded=False)
    ran: list[tuple[str, float]] = []

    def repeating(name: str, period_s: float, times: int) -> None:
        left = [times]

        def job(now_s: float) -> float | None:
            ran.append((name, now_s))
            left[0] -= 1
            return now_s + period_s if left[0] else None
        sender.at(clock.now_s + period_s, job)

    def broken(now_s: float) -> float | None:
        raise RuntimeError("a stream's send failed")

    repeating("fast", 1.0, 3)
    repeating("slow", 2.5, 2)
    sender.at(clock.now_s + 0.5, broken)
    assert sender.run_due(clock.now_s) == pytest.approx(100.5)  # nothing due yet
    fired_at = []
    while (next_s := sender.run_due(clock.now_s)) is not None:
        clock.now_s = next_s
        fired_at.append(next_s)
    assert ran == [("fast", 101.0), ("fast", 102.0), ("slow", 102.5), ("fast", 103.0),
                   ("slow", 105.0)]
    assert sender.jobs_failed == 1
    assert sender.pending() == 0


def _fake_streamer(rate_hz: float) -> tuple[SetpointStreamer, SenderThread, FakeClock,
                                             list[tuple[float, float]]]:
    clock = FakeClock()
    sender = SenderThread(clock, threaded=False)
    sent: list[tuple[float, float]] = []
    streamer = SetpointStreamer(lambda m: sent.append((clock.now_s, m.x)), rate_hz=rate_hz,
                                sender=sender)
    return streamer, sender, clock, sent


def _run_until(sender: SenderThread, clock: FakeClock, until_s: float) -> None:
    while (next_s := sender.run_due(clock.now_s)) is not None and next_s <= until_s:
        clock.now_s = next_s
    clock.now_s = until_s


async def test_threaded_streamer_sends_on_deadlines_rephases_on_change_and_stops() -> None:
    streamer, sender, clock, sent = _fake_streamer(rate_hz=2)
    streamer.stream(_msg(1))
    assert streamer.threaded  # a real-time loop: the sender thread keeps the time
    _run_until(sender, clock, 101.2)
    clock.now_s = 101.3
    streamer.stream(_msg(2))  # goes out at once, and the next ticks count from here
    _run_until(sender, clock, 102.4)
    streamer.update(_msg(3))  # changes what the next tick sends, not when
    _run_until(sender, clock, 102.9)
    streamer.stop()
    _run_until(sender, clock, 110.0)

    assert sent == [(100.0, 1), (100.5, 1), (101.0, 1), (101.3, 2), (101.8, 2), (102.3, 2),
                    (102.8, 3)]
    assert sender.pending() == 0  # the stopped stream's job ended
    stats = streamer.stats()
    assert not stats.active
    assert stats.sent == 7
    assert stats.since_last_ms == pytest.approx(7200)


async def test_threaded_streamer_sends_a_change_at_once_in_place_of_the_next_tick() -> None:
    """The sender thread's side of ``change``: at once, the ticks after it on their times;
    a second change within that period waits for the time the tick before the next was
    due (one frame a period, however often the input changes)."""
    streamer, sender, clock, sent = _fake_streamer(rate_hz=2)
    streamer.stream(_msg(1))
    _run_until(sender, clock, 100.6)
    clock.now_s = 100.7
    streamer.change(_msg(2))  # at once: in place of the tick due at 101.0
    clock.now_s = 100.8
    streamer.change(_msg(3))  # within the period of the one that went early: waits for 101.0
    _run_until(sender, clock, 102.1)
    streamer.stop()
    _run_until(sender, clock, 110.0)

    # (and 2 ms more: two frames never closer, an interval never two whole periods)
    assert [x for _, x in sent] == [1, 1, 2, 3, 3]
    assert [t for t, _ in sent] == pytest.approx([100.0, 100.5, 100.7, 101.002, 102.0])
    assert sender.pending() == 0


async def test_threaded_streamer_skips_missed_ticks_counts_the_gap_and_follows_a_rate_change(
) -> None:
    streamer, sender, clock, sent = _fake_streamer(rate_hz=50)
    streamer.stream(_msg(1))
    _run_until(sender, clock, 100.04)
    clock.now_s = 100.105  # the thread is held up 45 ms past its deadline at 100.06
    _run_until(sender, clock, 100.2)
    times = [round(t, 6) for t, _ in sent]
    assert times == [100.0, 100.02, 100.04, 100.105, 100.12, 100.14, 100.16, 100.18, 100.2]
    stats = streamer.stats()
    assert stats.gaps == 1
    assert stats.max_gap_ms == pytest.approx(65)
    streamer.rate_hz = 10  # re-phases from the last send
    _run_until(sender, clock, 100.5)
    assert [round(t, 6) for t, _ in sent[9:]] == [100.3, 100.4, 100.5]
    streamer.stop()


async def test_a_stream_on_the_sender_thread_keeps_time_while_the_loop_is_busy() -> None:
    sent: list[float] = []
    streamer = SetpointStreamer(lambda _m: sent.append(time.monotonic()), rate_hz=50)
    streamer.stream(_msg(1))
    try:
        assert streamer.threaded
        await asyncio.sleep(0.1)
        # the loop runs Python code for 0.4 s without yielding (JSON, GC, a slow handler)
        busy_from = time.monotonic()
        while time.monotonic() - busy_from < 0.4:
            sum(range(1000))
        busy_to = time.monotonic()
    finally:
        streamer.stop()
    during = [t for t in sent if busy_from < t < busy_to]
    # 20 ticks fall in the busy time; a loop-timed stream would send none of them
    assert len(during) >= 5, f"only {len(during)} sends while the loop was busy"


# -- Link.send from the loop and from other threads at once --

async def test_concurrent_sends_keep_sequence_contiguous_signed_and_recorded(
    tmp_path: Path,
) -> None:
    key = secrets.token_bytes(32)
    store = SigningKeyStore(tmp_path / "signing.key")
    store.replace_key(key)
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(0.2)
    frames: list[bytes] = []
    done = threading.Event()

    def receive() -> None:
        while not done.is_set():
            try:
                frames.append(receiver.recv(2048))
            except TimeoutError:
                continue

    reader = threading.Thread(target=receive, daemon=True)
    reader.start()
    per_sender = 3000
    link = await Link.open(f"udpout:127.0.0.1:{receiver.getsockname()[1]}",
                           log_dir=tmp_path / "logs", signing_store=store)
    try:
        streamer = SetpointStreamer(link.send, rate_hz=100)
        streamer.stream(_msg(7))  # the sender thread streams throughout

        def other_thread() -> None:
            for i in range(per_sender):
                link.send(MAV.command_long_encode(1, 1, 400, 0, i, 0, 0, 0, 0, 0, 0))
                if i % 20 == 0:
                    time.sleep(0.001)

        other = threading.Thread(target=other_thread)
        other.start()
        for i in range(per_sender):
            link.send(MAV.param_request_read_encode(1, 1, b"P", i))
            if i % 20 == 0:
                await asyncio.sleep(0.001)
        await asyncio.to_thread(other.join, 30.0)
        streamer.stop()
        sent = link.stats().frames_out
        await wait_for(lambda: len(frames) >= sent, 10.0, "every frame at the receiver")
        tlog_path = link.tlog_path
    finally:
        await link.close()
        done.set()
        reader.join(5.0)
        receiver.close()

    checker = mavlink.MAVLink(None)
    checker.signing.secret_key = key
    checker.signing.sign_outgoing = False
    decoded = []
    for frame in frames:
        # a bad or replayed (not increasing) signature decodes as BAD_DATA
        msgs = checker.parse_buffer(frame)
        assert msgs is not None
        assert len(msgs) == 1
        decoded.append(msgs[0])
    assert [m.get_type() for m in decoded if m.get_type() == "BAD_DATA"] == []
    assert all(m._signed for m in decoded)
    assert len(decoded) == sent
    seqs = [m.get_seq() for m in decoded]
    assert all((b - a) % 256 == 1 for a, b in itertools.pairwise(seqs)), \
        "sequence numbers skip or repeat: two sends interleaved"
    kinds = [m.get_type() for m in decoded]
    assert kinds.count("COMMAND_LONG") == per_sender
    assert kinds.count("PARAM_REQUEST_READ") == per_sender
    assert kinds.count("SET_POSITION_TARGET_LOCAL_NED") >= 10
    assert checker.signing.badsig_count == 0
    # every frame sent went to the tlog once, whichever thread sent it
    assert tlog_path is not None
    assert sorted(frame for _, frame in iter_tlog(tlog_path)) == sorted(frames)


def test_a_stream_nobody_stopped_ends_when_its_loop_closes() -> None:
    clock = FakeClock()
    sender = SenderThread(clock, threaded=False)
    sent: list[float] = []
    streamer = SetpointStreamer(lambda _m: sent.append(clock.now_s), rate_hz=10, sender=sender)

    async def start() -> None:
        streamer.stream(_msg(1))

    asyncio.run(start())  # runs the loop, then closes it
    _run_until(sender, clock, 101.0)
    assert sent == [100.0]
    assert sender.pending() == 0
    assert not streamer.active


def test_the_sender_thread_runs_real_time_when_the_os_allows_it() -> None:
    seen: list[int] = []
    started: list[int] = []

    def look(_now: float) -> None:
        seen.append(os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK)
        # a thread it starts runs at ordinary priority (reset on fork)
        child = threading.Thread(target=lambda: started.append(os.sched_getscheduler(0)))
        child.start()
        child.join()

    sender = SenderThread()
    sender.at(time.monotonic(), look)
    deadline_s = time.monotonic() + 5.0
    while not started and time.monotonic() < deadline_s:
        time.sleep(0.01)
    expected = os.SCHED_FIFO if may_run_real_time() else os.SCHED_OTHER
    assert seen == [expected]
    assert started == [os.SCHED_OTHER]
    # the calling thread keeps its ordinary scheduling
    assert os.sched_getscheduler(0) == os.SCHED_OTHER
