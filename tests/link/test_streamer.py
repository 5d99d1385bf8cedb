"""The setpoint streamer's clock: absolute deadlines, immediate send on change, statistics."""

from __future__ import annotations

import asyncio
import time

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.streamer import SetpointStreamer
from tests.link.conftest import wait_for

MAV = mavlink.MAVLink(None)


def _msg(x: float) -> mavlink.MAVLink_message:
    return MAV.set_position_target_local_ned_encode(
        0, 1, 1, 1, 2552, x, 0, -5, 0, 0, 0, 0, 0, 0, 0, 0
    )


class _Recorder:
    def __init__(self) -> None:
        self.sent: list[tuple[float, float]] = []  # (loop time, x)

    def __call__(self, msg: mavlink.MAVLink_message) -> None:
        self.sent.append((asyncio.get_running_loop().time(), msg.x))


async def test_ticks_fall_on_absolute_deadlines_at_the_configured_rate() -> None:
    rec = _Recorder()
    streamer = SetpointStreamer(rec, rate_hz=50)
    streamer.stream(_msg(1))
    await wait_for(lambda: len(rec.sent) >= 26, 3.0)
    streamer.stop()

    t0 = rec.sent[0][0]
    # each send is near t0 + k/50: lateness does not accumulate over the run
    lateness = [t - (t0 + k * 0.02) for k, (t, _) in enumerate(rec.sent[:26])]
    assert max(abs(x) for x in lateness) < 0.04
    stats = streamer.stats()
    assert stats.sent == len(rec.sent)
    assert stats.interval_p50_ms == pytest.approx(20, abs=5)
    assert stats.rate_hz == pytest.approx(50, rel=0.2)
    assert not stats.active


async def test_changed_setpoint_goes_out_at_once_and_rephases() -> None:
    rec = _Recorder()
    streamer = SetpointStreamer(rec, rate_hz=2)  # slow, so "at once" is clearly not a tick
    streamer.stream(_msg(1))
    await asyncio.sleep(0.05)
    changed_at = asyncio.get_running_loop().time()
    streamer.stream(_msg(2))
    await wait_for(lambda: len(rec.sent) >= 3, 2.0)
    streamer.stop()

    (_t1, x1), (t2, x2), (t3, x3) = rec.sent[:3]
    assert (x1, x2, x3) == (1, 2, 2)
    assert t2 - changed_at < 0.005
    assert t3 - t2 == pytest.approx(0.5, abs=0.05)  # next tick counts from the change


async def test_a_stalled_loop_skips_missed_ticks_and_counts_a_gap() -> None:
    rec = _Recorder()
    streamer = SetpointStreamer(rec, rate_hz=50)
    streamer.stream(_msg(1))
    await asyncio.sleep(0.1)
    time.sleep(0.2)  # noqa: ASYNC251 - blocks the event loop for ten periods on purpose
    stall_end = asyncio.get_running_loop().time()
    await asyncio.sleep(0.1)
    streamer.stop()
    end = asyncio.get_running_loop().time()
    after = [t for t, _ in rec.sent if t >= stall_end]
    stats = streamer.stats()
    # the ten missed ticks are skipped, not sent in a catch-up burst
    assert len(after) <= (end - stall_end) * 50 + 2
    assert stats.gaps >= 1
    assert stats.max_gap_ms is not None
    assert stats.max_gap_ms >= 190


async def test_stop_ends_the_stream() -> None:
    rec = _Recorder()
    streamer = SetpointStreamer(rec, rate_hz=100)
    streamer.stream(_msg(1))
    await asyncio.sleep(0.05)
    streamer.stop()
    count = len(rec.sent)
    await asyncio.sleep(0.05)

    assert len(rec.sent) == count
    assert streamer.stats().since_last_ms is not None


@pytest.mark.parametrize("rate_hz", [1.0, 101.0])
def test_rate_outside_2_to_100_hz_is_refused(rate_hz: float) -> None:
    with pytest.raises(ValueError, match=r"2\.\.100"):
        SetpointStreamer(lambda _m: None, rate_hz=rate_hz)


async def test_rate_change_while_streaming_takes_effect() -> None:
    rec = _Recorder()
    streamer = SetpointStreamer(rec, rate_hz=10)
    streamer.stream(_msg(1))
    await asyncio.sleep(0.05)
    streamer.rate_hz = 100
    start = len(rec.sent)
    await asyncio.sleep(0.2)
    streamer.stop()

    assert len(rec.sent) - start >= 12


async def test_reported_rate_follows_a_rate_change() -> None:
    rec = _Recorder()
    streamer = SetpointStreamer(rec, rate_hz=10)
    streamer.stream(_msg(1))
    await asyncio.sleep(0.5)
    streamer.rate_hz = 50
    await asyncio.sleep(1.3)
    streamer.stop()

    assert streamer.stats().rate_hz == pytest.approx(50, rel=0.2)


async def test_statistics_restart_with_the_stream() -> None:
    sent: list[object] = []
    streamer = SetpointStreamer(sent.append, rate_hz=50.0)
    streamer.stream(_msg(1.0))
    await asyncio.sleep(0.2)
    streamer.stop()
    first = streamer.stats()
    await asyncio.sleep(0.15)

    streamer.stream(_msg(2.0))
    await asyncio.sleep(0.05)
    streamer.stop()
    second = streamer.stats()

    assert first.sent >= 8
    # the pause between the two streams is neither an interval nor a gap of the second one
    assert second.sent < first.sent
    assert second.max_gap_ms is not None
    assert second.max_gap_ms < 100.0
    assert second.gaps == 0
