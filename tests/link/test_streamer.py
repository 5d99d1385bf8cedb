"""The setpoint streamer's clock: absolute deadlines, immediate send on change, statistics.

Every test runs on virtual loop time (looptime), so times are exact: a send due at
t0 + k·period happens at that loop time, not somewhere near it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, cast

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.stream.sender_supervisor import STARVED_AFTER_S, STUCK_AFTER_S
from server.link.stream.streamer import SetpointStreamer

pytestmark = pytest.mark.looptime

MAV = mavlink.MAVLink(None)
# Exact to floating-point rounding: virtual time has no jitter.
EXACT_S = 1e-9


def _msg(x: float) -> mavlink.MAVLink_message:
    return MAV.set_position_target_local_ned_encode(
        0, 1, 1, 1, 2552, x, 0, -5, 0, 0, 0, 0, 0, 0, 0, 0
    )


class _Recorder:
    """A sender that records (loop time, x) of every send. A send can cost loop time, as a
    slow transport write or a busy loop would: the clock moves on by ``cost_s(index)``
    while the send runs, so whatever the streamer schedules after it sees the later time."""

    def __init__(
        self, monkeypatch: pytest.MonkeyPatch, cost_s: Callable[[int], float] = lambda _: 0.0
    ) -> None:
        self.sent: list[tuple[float, float]] = []
        self._cost_s = cost_s
        self._spent_s = 0.0
        self._loop = asyncio.get_running_loop()
        loop_time = self._loop.time
        # asyncio schedules and fires timers by loop.time(), so this is the clock everyone sees
        monkeypatch.setattr(self._loop, "time", lambda: loop_time() + self._spent_s)

    def __call__(self, msg: mavlink.MAVLink_message) -> None:
        self.sent.append((self._loop.time(), msg.x))
        self.spend(self._cost_s(len(self.sent) - 1))

    def spend(self, duration_s: float) -> None:
        """Hold the loop for ``duration_s`` of virtual time, as blocking work would."""
        self._spent_s += duration_s

    @property
    def times(self) -> list[float]:
        return [t for t, _ in self.sent]


def _now() -> float:
    return asyncio.get_running_loop().time()


def _assert_times(actual: list[float], expected: list[float]) -> None:
    assert len(actual) == len(expected)
    worst = max((abs(a - e), k) for k, (a, e) in enumerate(zip(actual, expected, strict=True)))
    assert worst[0] < EXACT_S, f"send {worst[1]} is {worst[0]:.3g} s off its deadline"


async def test_every_send_is_on_its_absolute_deadline_even_when_sends_cost_time(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    periods = 5000
    # each send takes 0..15 ms of a 20 ms period: a "sleep one period after sending"
    # schedule would drift by the sum of these, the deadline schedule must not move at all
    rec = _Recorder(monkeypatch, cost_s=lambda k: (k * 7 % 16) * 0.001)
    streamer = SetpointStreamer(rec, rate_hz=50)
    streamer.stream(_msg(1))
    t0 = rec.times[0]
    # and every tenth tick finds the loop busy until 3 ms after its deadline: that send is
    # 3 ms late, the one after it on time again (lateness never carries over)
    late_ticks = range(5, periods + 1, 10)
    for k in late_ticks:
        asyncio.get_running_loop().call_at(t0 + k * 0.02 - 0.001, rec.spend, 0.004)
    await asyncio.sleep(t0 + periods * 0.02 + 0.01 - _now())
    stats = streamer.stats()
    streamer.stop()

    late_s = [0.003 if k in late_ticks else 0.0 for k in range(periods + 1)]
    _assert_times(rec.times, [t0 + k * 0.02 + late_s[k] for k in range(periods + 1)])
    assert stats.sent == periods + 1
    assert stats.gaps == 0
    assert stats.rate_hz == pytest.approx(50, rel=1e-9)
    assert stats.interval_p50_ms == pytest.approx(20, rel=1e-9)
    assert stats.interval_p99_ms == pytest.approx(23, rel=1e-9)
    assert stats.max_gap_ms == pytest.approx(23, rel=1e-9)
    assert stats.since_last_ms == pytest.approx(10, rel=1e-6)
    assert stats.active


async def test_changed_setpoint_goes_out_at_once_and_rephases(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rec = _Recorder(monkeypatch)
    streamer = SetpointStreamer(rec, rate_hz=2)  # slow, so "at once" is clearly not a tick
    streamer.stream(_msg(1))
    t0 = rec.times[0]
    await asyncio.sleep(0.05)
    changed_at = _now()
    streamer.stream(_msg(2))
    await asyncio.sleep(1.2)
    streamer.stop()

    assert [x for _, x in rec.sent] == [1, 2, 2, 2]
    assert changed_at == pytest.approx(t0 + 0.05, abs=EXACT_S)
    # the next ticks count from the change, not from the first stream
    _assert_times(rec.times, [t0, changed_at, changed_at + 0.5, changed_at + 1.0])


async def test_a_send_that_overruns_skips_missed_ticks_and_counts_a_gap(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # send 5 holds the loop for 210 ms, ten and a half periods at 50 Hz
    rec = _Recorder(monkeypatch, cost_s=lambda k: 0.21 if k == 5 else 0.0)
    streamer = SetpointStreamer(rec, rate_hz=50)
    streamer.stream(_msg(1))
    t0 = rec.times[0]
    await asyncio.sleep(t0 + 0.4 + 0.01 - _now())
    streamer.stop()
    stats = streamer.stats()

    # the overdue tick goes as soon as the loop is free; the ten missed ones are skipped,
    # not sent in a burst; then the sends are back on the original grid
    on_time = [t0 + k * 0.02 for k in range(6)]
    late = t0 + 0.1 + 0.21
    back_on_grid = [t0 + k * 0.02 for k in range(16, 21)]
    _assert_times(rec.times, [*on_time, late, *back_on_grid])
    assert stats.gaps == 1
    assert stats.max_gap_ms == pytest.approx(210, rel=1e-9)


async def test_stop_ends_the_stream(monkeypatch: pytest.MonkeyPatch) -> None:
    rec = _Recorder(monkeypatch)
    streamer = SetpointStreamer(rec, rate_hz=100)
    streamer.stream(_msg(1))
    t0 = rec.times[0]
    await asyncio.sleep(0.055)
    streamer.stop()
    await asyncio.sleep(1.0)

    _assert_times(rec.times, [t0 + k * 0.01 for k in range(6)])
    stats = streamer.stats()
    assert not stats.active
    assert stats.since_last_ms == pytest.approx(1005, rel=1e-9)
    assert streamer.streaming_for_s() == 0.0


async def test_a_stopped_stream_reports_no_rate(monkeypatch: pytest.MonkeyPatch) -> None:
    """Stopped, nothing leaves: its rate is 0, not the last second's 20 Hz of a minute ago;
    the figures since it started (sent, percentiles, largest gap) stay for the record."""
    rec = _Recorder(monkeypatch)
    streamer = SetpointStreamer(rec, rate_hz=20)
    streamer.stream(_msg(1))
    await asyncio.sleep(1.02)
    assert streamer.stats().rate_hz == pytest.approx(20, rel=1e-6)
    streamer.stop()
    await asyncio.sleep(60.0)

    stats = streamer.stats()
    assert not stats.active
    assert stats.rate_hz == 0.0
    assert stats.sent == 21
    assert stats.interval_p99_ms == pytest.approx(50, rel=1e-6)


class _SilentFor:
    """A sender process as the streamer sees it: silent for ``age_s`` (None: it ended)."""

    def __init__(self, age_s: float | None) -> None:
        self.process = self
        self.age_s = age_s

    def heartbeat_age_s(self) -> float | None:
        return self.age_s


@pytest.mark.parametrize(
    ("silent_s", "active"),
    [(0.1, True), (0.3, True), (STARVED_AFTER_S - 0.01, True), (STARVED_AFTER_S, False),
     (2.0, False), (None, False)],
)
async def test_a_sender_kept_waiting_for_a_core_still_streams_a_silent_or_ended_one_not(
    monkeypatch: pytest.MonkeyPatch, silent_s: float | None, active: bool
) -> None:
    """A busy machine keeps the sender process from its core for a few tenths of a second:
    its stream is still active (the supervisor's watchdog, which kills a stopped process
    once silent for STUCK_AFTER_S, leaves it too); a page reading `active` flip-flop with the
    machine's load would show the stream stopped and back. Silent for STARVED_AFTER_S, or
    ended, it is not."""
    assert STUCK_AFTER_S < 0.3 < STARVED_AFTER_S
    streamer = SetpointStreamer(_Recorder(monkeypatch), rate_hz=20)
    streamer.stream(_msg(1))
    await asyncio.sleep(0.2)
    assert streamer.stats().active
    streamer._channel = cast(Any, _SilentFor(silent_s))  # as while a process times it
    try:
        assert streamer.stats().active is active
    finally:
        streamer._channel = None
        streamer.stop()


@pytest.mark.parametrize("rate_hz", [1.0, 101.0])
def test_rate_outside_2_to_100_hz_is_refused(rate_hz: float) -> None:
    with pytest.raises(ValueError, match=r"2\.\.100"):
        SetpointStreamer(lambda _m: None, rate_hz=rate_hz)


async def test_rate_change_while_streaming_counts_from_the_last_send(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rec = _Recorder(monkeypatch)
    streamer = SetpointStreamer(rec, rate_hz=10)
    streamer.stream(_msg(1))
    t0 = rec.times[0]
    await asyncio.sleep(0.055)
    streamer.rate_hz = 100
    await asyncio.sleep(0.2)
    streamer.stop()

    # t0 + 10 ms is already past at the change: that tick goes at once, the rest on the
    # 100 Hz grid from t0
    _assert_times(rec.times, [t0, t0 + 0.055, *(t0 + k * 0.01 for k in range(6, 26))])


async def test_reported_rate_follows_a_rate_change(monkeypatch: pytest.MonkeyPatch) -> None:
    rec = _Recorder(monkeypatch)
    streamer = SetpointStreamer(rec, rate_hz=10)
    streamer.stream(_msg(1))
    await asyncio.sleep(0.55)
    assert streamer.stats().rate_hz == pytest.approx(10, rel=1e-9)
    streamer.rate_hz = 50
    await asyncio.sleep(1.3)

    assert streamer.stats().rate_hz == pytest.approx(50, rel=1e-9)
    streamer.stop()


async def test_statistics_restart_with_the_stream(monkeypatch: pytest.MonkeyPatch) -> None:
    rec = _Recorder(monkeypatch)
    streamer = SetpointStreamer(rec, rate_hz=50.0)
    streamer.stream(_msg(1.0))
    await asyncio.sleep(0.205)
    assert streamer.streaming_for_s() == pytest.approx(0.205, abs=EXACT_S)
    streamer.stop()
    first = streamer.stats()
    await asyncio.sleep(0.15)

    streamer.stream(_msg(2.0))
    await asyncio.sleep(0.055)
    streamer.stop()
    second = streamer.stats()

    assert first.sent == 11
    # the pause between the two streams is neither an interval nor a gap of the second one
    assert second.sent == 3
    assert second.max_gap_ms == pytest.approx(20, rel=1e-9)
    assert second.gaps == 0


async def test_update_keeps_the_schedule_however_often_the_message_changes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """MANUAL_CONTROL's way: new sticks change what the next tick sends, never when."""
    rec = _Recorder(monkeypatch)
    streamer = SetpointStreamer(rec, rate_hz=25.0)
    t0 = _now()
    streamer.update(_msg(0.0))  # a stopped stream starts at once
    for k in range(1, 60):  # 60 updates a second for one second
        await asyncio.sleep(1.0 / 60.0)
        streamer.update(_msg(float(k)))
    await asyncio.sleep(0.001)
    streamer.stop()
    expected = [t0 + k * 0.04 for k in range(len(rec.times))]
    assert rec.times == pytest.approx(expected, abs=EXACT_S)
    assert len(rec.times) == 25  # 0 .. 0.96 s, never an extra send for an update
    # each tick sends the newest message given before it
    for t, x in rec.sent[1:]:
        assert x == pytest.approx(int((t - t0) * 60.0 + 1e-6), abs=1.0)


async def test_a_change_goes_out_at_once_in_place_of_the_next_tick(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A pilot's input (sticks, keys): sent when it comes, not at the next tick; the ticks
    after it keep their times, so the stream sends no more frames than before."""
    rec = _Recorder(monkeypatch)
    streamer = SetpointStreamer(rec, rate_hz=2.0)  # slow, so "at once" is clearly not a tick
    streamer.stream(_msg(1))
    t0 = rec.times[0]
    await asyncio.sleep(0.6)  # the tick at t0 + 0.5 went
    changed_at = _now()
    streamer.change(_msg(2))
    await asyncio.sleep(1.5)
    streamer.stop()

    assert [x for _, x in rec.sent] == [1, 1, 2, 2, 2]
    # the change at once (it took the place of the tick at t0 + 1.0), the ticks on their times
    _assert_times(rec.times, [t0, t0 + 0.5, changed_at, t0 + 1.5, t0 + 2.0])
    assert changed_at == pytest.approx(t0 + 0.6, abs=EXACT_S)


async def test_changes_faster_than_the_rate_never_raise_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Sticks changing at 60 Hz on a 25 Hz stream: the first change goes at once, the
    others each wait for the time the tick before the next was due: one frame a period."""
    rec = _Recorder(monkeypatch)
    streamer = SetpointStreamer(rec, rate_hz=25.0)
    t0 = _now()
    streamer.change(_msg(0.0))  # a stopped stream starts at once
    for k in range(1, 60):  # 60 changes a second for one second
        await asyncio.sleep(1.0 / 60.0)
        streamer.change(_msg(float(k)))
    await asyncio.sleep(0.001)
    streamer.stop()
    # the n-th frame never goes before the (n-1)-th tick was due: at most one frame more
    # than the ticks alone would have sent in the second, never two early in a period
    assert len(rec.times) <= 26
    for n, t in enumerate(rec.times[1:], start=1):
        assert t >= t0 + (n - 1) * 0.04 - EXACT_S, f"frame {n} ahead of the schedule"
    # and each frame is the newest input given by then, sent when it came or when the
    # period it waits for began: no frame waits longer than a period
    for t, x in rec.sent[1:]:
        given_at = t0 + x / 60.0
        assert given_at - EXACT_S <= t <= given_at + 0.04 + EXACT_S


async def test_a_repeated_change_of_a_stopped_stream_starts_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rec = _Recorder(monkeypatch)
    streamer = SetpointStreamer(rec, rate_hz=10.0)
    streamer.change(_msg(1))
    await asyncio.sleep(0.25)
    streamer.stop()
    streamer.change(_msg(2))
    await asyncio.sleep(0.05)
    streamer.stop()
    assert [x for _, x in rec.sent] == [1, 1, 1, 2]
