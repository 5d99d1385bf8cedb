"""The offboard setpoint streamer: one per vehicle, on absolute deadlines.

Ticks fall on t0 + k·period, so a late tick does not push every later one back; a tick that
comes too late to matter is skipped and shows up as a gap. A new setpoint goes out at once
(from the caller, on the loop) and re-phases the schedule. A changed frame of a running
stream (``change``: a pilot's sticks) goes out at once too, in place of the next tick: the
ticks after it keep their times, and a change within a period of one that went early waits
for the time the tick before the next was due, so the rate never rises however often the
input changes (``Deadlines.early_s``).

Who keeps the time, on a real clock: the server's setpoint sender process
(server.link.stream.stream_process, through a ``channel`` of the link: UDP links), which needs
neither the GIL nor the event loop; where there is none (TCP, serial, a process that cannot
run), the process's sender thread (server.link.stream.stream_thread). Under a virtual loop clock
(looptime in tests) the event loop itself (loop.call_at), so virtual time drives the stream
exactly. SKYHELM_STREAM_SENDER (``process``, ``thread`` or ``loop``) caps the choice;
bench/stream_vs_mavsdk.py and bench/stream_contention.py compare them.

A stream outlives its sender process: when the process dies or stops answering, its
supervisor (server.link.stream.sender_supervisor) moves the stream to the sender thread at
once, with its current setpoint and schedule, and back to a restarted process later; the
stream's ``on_sender_change`` hears of both (the ``stream`` event).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import threading
import time
from array import array
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.snapshot import StreamStats
from server.link.stream.sender_supervisor import STARVED_AFTER_S, ProcessGone
from server.link.stream.stream_channel import StreamChannel, supervisor
from server.link.stream.stream_thread import Deadlines, SenderThread, shared_sender

MIN_RATE_HZ = 2.0
MAX_RATE_HZ = 100.0
DEFAULT_RATE_HZ = 20.0
# An interval longer than this many periods counts as a gap.
GAP_PERIODS = 2.0
# Who times streams on a real clock: "process" (the sender process where the link has one,
# else the thread), "thread" (the sender thread) or "loop" (the event loop).
SENDER = os.environ.get("SKYHELM_STREAM_SENDER", "process")
SENDER_THREAD = SENDER != "loop"
# A stream in the sender process: given the callback for its tick times, a channel or None.
ChannelFactory = Callable[[Callable[[int, list[float]], None]], StreamChannel | None]


def _real_time_loop(loop: asyncio.AbstractEventLoop) -> bool:
    """Whether the loop keeps real time (asyncio's and uvloop's loops do): not a clock
    patched on the instance, nor looptime's virtual time (its loops say ``looptime_on``)."""
    return "time" not in vars(loop) and not getattr(loop, "looptime_on", False)


class SetpointStreamer:
    def __init__(
        self,
        send: Callable[[mavlink.MAVLink_message], None],
        *,
        rate_hz: float = DEFAULT_RATE_HZ,
        window: int = 1024,
        sender: SenderThread | None = None,
        channel: ChannelFactory | None = None,
    ) -> None:
        self._send = send
        self._channel_factory = channel
        self._channel: StreamChannel | None = None  # set while the process times the stream
        # on the thread for want of the process (lost, being restarted): back when it runs
        self._fell_back = False
        # told (on the loop) when the stream changes sender after a fault: a dict for the
        # ``stream`` event
        self.on_sender_change: Callable[[dict[str, Any]], None] | None = None
        self._sid: int | None = None
        self._deadlines = Deadlines(1.0 / self._checked_rate(rate_hz))
        self._msg: mavlink.MAVLink_message | None = None
        self._active = False
        # the loop-timed schedule's timer; the thread's jobs carry the generation they
        # were scheduled in and end when it has moved on (stop, re-phase)
        self._handle: asyncio.TimerHandle | None = None
        self._generation = 0
        self._sender = sender
        self._threaded = False
        self._clock: Callable[[], float] = time.monotonic
        self._loop: asyncio.AbstractEventLoop | None = None
        # the loop (stream, update, stop, stats) and the sender thread (ticks) share the
        # state below; the sends themselves are serialised by the link
        self._lock = threading.RLock()
        self._started_s: float | None = None
        # statistics; the interval window is preallocated and overwritten in a ring
        self._intervals = array("d", bytes(8 * window))
        self._reset_stats()
        if channel is not None:
            supervisor().watch(self)

    @property
    def _period_s(self) -> float:
        return self._deadlines.period_s

    @staticmethod
    def _checked_rate(rate_hz: float) -> float:
        if not MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ:
            raise ValueError(f"stream rate must be {MIN_RATE_HZ:g}..{MAX_RATE_HZ:g} Hz")
        return rate_hz

    @property
    def rate_hz(self) -> float:
        return 1.0 / self._period_s

    @rate_hz.setter
    def rate_hz(self, rate_hz: float) -> None:
        period_s = 1.0 / self._checked_rate(rate_hz)
        with self._lock:
            self._deadlines.period_s = period_s
            if self.active and self._channel is not None:
                self._channel.period(period_s)
            elif self.active:
                self._rephase()

    @property
    def active(self) -> bool:
        return self._active

    @property
    def threaded(self) -> bool:
        """Whether the sender thread (not the event loop) times this stream."""
        return self._threaded

    @property
    def in_process(self) -> bool:
        """Whether the sender process times this stream."""
        return self._channel is not None

    def stream(self, msg: mavlink.MAVLink_message) -> None:
        """Send ``msg`` now and then every period until stop() or the next stream()."""
        loop = asyncio.get_running_loop()
        with self._lock:
            if not self._active:
                self._choose_clock(loop)
            self._msg = msg
            if self._started_s is None:
                # statistics describe the stream since it last started
                self._reset_stats()
                self._started_s = self._clock()
            self._active = True
            if self._channel is not None and self._stream_in_process(msg):
                return
            self._emit(self._clock())
            self._rephase()

    def _stream_in_process(self, msg: mavlink.MAVLink_message) -> bool:
        """Send now and re-phase in the sender process; False (and the thread from now on)
        once the process has ended."""
        assert self._channel is not None
        try:
            self._sid = self._channel.stream(msg, self._period_s)
        except ProcessGone:
            self._channel = None
            self._fell_back = True
            self._choose_thread()
            return False
        return True

    def _choose_clock(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._channel = None
        self._fell_back = False
        real_time = _real_time_loop(loop)
        if real_time and SENDER == "process" and self._channel_factory is not None:
            self._channel = self._channel_factory(self._process_ticks)
            if self._channel is not None:
                self._threaded = False
                self._clock = time.monotonic  # the process's clock: CLOCK_MONOTONIC
                if SENDER_THREAD:  # the thread that takes over a lost process runs already
                    self._thread_sender().start()
                return
            self._fell_back = True  # where the link has no process, sender_back finds none
        self._choose_thread()

    def _choose_thread(self) -> None:
        assert self._loop is not None
        self._threaded = SENDER_THREAD and _real_time_loop(self._loop)
        if self._threaded:
            self._clock = self._thread_sender().clock
        else:
            self._clock = self._loop.time

    def _thread_sender(self) -> SenderThread:
        """The sender thread this stream falls to: the one given, or the process's."""
        if self._sender is None:
            self._sender = shared_sender()
        return self._sender

    def update(self, msg: mavlink.MAVLink_message) -> None:
        """Send ``msg`` from the next tick on without moving the schedule (a stream that
        must keep its rate whatever the rate of its updates); stream() it when stopped."""
        with self._lock:
            if self.active:
                self._msg = msg
                if self._channel is not None:
                    try:
                        self._channel.update(msg)
                    except ProcessGone:  # the thread goes on with it
                        self._to_thread()
                return
        self.stream(msg)

    def change(self, msg: mavlink.MAVLink_message) -> None:
        """Send a changed ``msg`` now in place of the next tick; the ticks after it keep
        their times (a change within a period of one sent early waits for the time the
        tick before the next was due: the rate stays). stream() it when stopped."""
        with self._lock:
            if self.active:
                self._msg = msg
                if self._channel is not None:
                    try:
                        self._channel.change(msg)
                        return
                    except ProcessGone:  # the thread goes on with it
                        self._to_thread()
                now = self._clock()
                early_s = self._deadlines.early_s()
                if now >= early_s:
                    self._emit(now)
                    self._schedule(self._deadlines.after_tick(now))
                else:
                    self._schedule(early_s)
                return
        self.stream(msg)

    # -- the sender process's supervisor --
    def sender_lost(self, process: object) -> None:
        """The process timing this stream is gone: the thread takes the stream over now,
        with its current setpoint, on its schedule (a tick already due goes at once)."""
        with self._lock:
            if self._channel is None or self._channel.process is not process:
                return
            was_active = self._active
            self._to_thread()
        if was_active:
            self._tell({"sender": "thread", "fault": supervisor().last_fault})

    def _to_thread(self) -> None:
        with self._lock:
            self._channel = None
            self._sid = None
            self._fell_back = True
            self._choose_thread()
            if self._active:
                self._rephase()

    def sender_back(self) -> None:
        """A new process runs: the stream moves back to it (its first frame goes at once)."""
        with self._lock:
            if not self._fell_back or self._channel is not None:
                return
            if not self._active or self._msg is None or self._loop is None:
                self._fell_back = False
                return
            channel = self._channel_factory(self._process_ticks) if self._channel_factory else None
            if channel is None:
                return
            self._generation += 1  # the thread's jobs end
            self._channel = channel
            self._fell_back = False
            self._threaded = False
            self._clock = time.monotonic
            if not self._stream_in_process(self._msg):
                self._rephase()
                return
        self._tell({"sender": "process", "recovered": True})

    def streams_in(self, process: object) -> bool:
        """Whether this stream runs in ``process`` now (the supervisor's watchdog asks)."""
        channel = self._channel
        return self._active and channel is not None and channel.process is process

    def _tell(self, data: dict[str, Any]) -> None:
        listener, loop = self.on_sender_change, self._loop
        if listener is None or loop is None:
            return
        status = supervisor().status()
        data = {**data, "restarts": status.restarts, "gave_up": status.gave_up}
        with contextlib.suppress(RuntimeError):  # the loop has closed
            loop.call_soon_threadsafe(listener, data)

    @property
    def sender(self) -> str:
        """Who sends this stream's frames now: "process", "thread" or "loop" ("none" while
        it is stopped)."""
        if not self._active:
            return "none"
        if self._channel is not None:
            return "process"
        return "thread" if self._threaded else "loop"

    def _frames_leaving(self) -> bool:
        """Active, and its sender is running: a process that ended is not, nor one silent
        for STARVED_AFTER_S. One stopped (SIGSTOP) is killed by the supervisor's watchdog
        once silent for STUCK_AFTER_S, and so ends; one a busy machine keeps waiting for a
        core a few tenths of a second still streams (its frames leave once it runs, well
        within the vehicle's offboard timeout), as the watchdog judges it: a flag that
        flickered with the machine's load would tell a page the stream had stopped."""
        if not self._active:
            return False
        channel = self._channel
        if channel is None:
            return True
        age_s = channel.process.heartbeat_age_s()
        return age_s is not None and age_s < STARVED_AFTER_S

    def _reset_stats(self) -> None:
        self._ring_next = 0
        self._ring_len = 0
        self._sent = 0
        self._gaps = 0
        self._max_interval_s = 0.0
        self._last_s: float | None = None
        # (sent count they were computed at, p50 s, p99 s): snapshots ask far more often
        # than intervals are added, and sorting the window is the costly part
        self._percentiles: tuple[int, float, float] | None = None

    def stop(self) -> None:
        with self._lock:
            self._generation += 1
            if self._handle is not None:
                self._handle.cancel()
                self._handle = None
            if self._channel is not None:
                self._channel.stop()  # its last ticks still come, under the same id
            self._active = False
            self._msg = None
            self._started_s = None

    def streaming_for_s(self) -> float:
        """How long the current stream has run without a stop (0 when stopped)."""
        if self._started_s is None:
            return 0.0
        return self._clock() - self._started_s

    def _rephase(self) -> None:
        self._schedule(self._deadlines.rephase(
            self._last_s if self._last_s is not None else self._clock()))

    def _schedule(self, first_s: float) -> None:
        """The next tick at ``first_s`` (the jobs and timers of before end)."""
        self._generation += 1
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
        if self._threaded:
            assert self._sender is not None
            generation = self._generation
            self._sender.at(first_s, lambda now_s: self._thread_tick(generation))
        else:
            assert self._loop is not None
            self._handle = self._loop.call_at(first_s, self._loop_tick)

    def _thread_tick(self, generation: int) -> float | None:
        """A tick on the sender thread; its next deadline, or None once stopped/re-phased."""
        with self._lock:
            if generation != self._generation:
                return None
            if self._loop is not None and self._loop.is_closed():
                # its owner's loop is gone (a stream nobody stopped): it ends with it
                self._active = False
                return None
            now = self._clock()
            self._emit(now)
            return self._deadlines.after_tick(now)

    def _loop_tick(self) -> None:
        assert self._loop is not None
        now = self._loop.time()
        self._emit(now)
        self._handle = self._loop.call_at(self._deadlines.after_tick(now), self._loop_tick)

    def _process_ticks(self, sid: int, times: list[float]) -> None:
        """Ticks the sender process made (its reader thread calls this)."""
        with self._lock:
            if sid != self._sid:
                return  # a stream before the current one
            for now in times:
                self._record(now)

    def _emit(self, now: float) -> None:
        if self._msg is None:
            return
        self._send(self._msg)
        self._record(now)

    def _record(self, now: float) -> None:
        if self._last_s is not None:
            interval = now - self._last_s
            self._intervals[self._ring_next] = interval
            self._ring_next = (self._ring_next + 1) % len(self._intervals)
            self._ring_len = min(self._ring_len + 1, len(self._intervals))
            if interval > GAP_PERIODS * self._period_s:
                self._gaps += 1
            self._max_interval_s = max(self._max_interval_s, interval)
        self._last_s = now
        self._sent += 1

    def stats(self) -> StreamStats:
        with self._lock:
            return self._stats()

    def _stats(self) -> StreamStats:
        since_last_ms = None
        if self._last_s is not None:
            since_last_ms = (self._clock() - self._last_s) * 1000.0
        restarts, fault = 0, None
        if self._channel_factory is not None:
            status = supervisor().status()
            restarts, fault = status.restarts, status.last_fault
        if not self._ring_len:
            return StreamStats(active=self._frames_leaving(), sent=self._sent,
                               since_last_ms=since_last_ms, sender=self.sender,
                               sender_restarts=restarts, sender_fault=fault)
        # the rate over the last ~1 s, so it follows a rate change; percentiles use the window.
        # No frame leaves a stopped stream (or a stuck sender): its rate is 0, not the last
        # second's before it stopped.
        leaving = self._frames_leaving()
        recent = self._recent(max(2, round(self.rate_hz)))
        if self._percentiles is None or self._percentiles[0] != self._sent:
            ordered = sorted(self._intervals[: self._ring_len])
            self._percentiles = (self._sent, _percentile(ordered, 0.50), _percentile(ordered, 0.99))
        _, p50_s, p99_s = self._percentiles
        return StreamStats(
            active=leaving,
            rate_hz=len(recent) / sum(recent) if leaving and sum(recent) > 0 else 0.0,
            interval_p50_ms=p50_s * 1000.0,
            interval_p99_ms=p99_s * 1000.0,
            max_gap_ms=self._max_interval_s * 1000.0,
            gaps=self._gaps,
            sent=self._sent,
            since_last_ms=since_last_ms,
            sender=self.sender,
            sender_restarts=restarts,
            sender_fault=fault,
        )

    def _recent(self, count: int) -> list[float]:
        """The last ``count`` recorded intervals (fewer if fewer were recorded)."""
        size = len(self._intervals)
        return [
            self._intervals[(self._ring_next - 1 - i) % size]
            for i in range(min(count, self._ring_len))
        ]


def sender_event(stream: str, change: dict[str, Any]) -> dict[str, object]:
    """The ``stream`` event of a sender change (``on_sender_change``'s argument) of the
    stream named ``stream`` ("offboard" or "sticks")."""
    if change.get("recovered"):
        text = f"{stream} stream back on a restarted setpoint sender process"
    elif change.get("gave_up"):
        text = (f"{stream} stream goes on from the server's sender thread: the setpoint sender "
                f"process failed ({change.get('fault')}) and is not restarted again")
    else:
        text = (f"{stream} stream goes on from the server's sender thread: the setpoint sender "
                f"process failed ({change.get('fault')}); restarting it")
    return {"active": True, "stream": stream, **change, "text": text}


def _percentile(ordered: list[float], q: float) -> float:
    """Nearest-rank percentile of an ascending list."""
    rank = max(1, math.ceil(q * len(ordered)))
    return ordered[rank - 1]
