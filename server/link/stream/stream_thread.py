"""The setpoint sender thread: every stream of the process on absolute deadlines, off the loop.

The web server's event loop encodes JSON, answers REST reads and collects garbage; a stream
timed by that loop is late whenever it is busy. One daemon thread per process instead keeps a
heap of (deadline, job) on ``time.monotonic`` and sleeps on a condition until the earliest
is due; a job sends its frame and answers its next deadline (or None: it is over). Deadline
math (:class:`Deadlines`, from the sender process's module) is shared with the loop-timed streamer.

A thread still needs the GIL to send, and CPython hands it over only every switch interval
(5 ms by default) while the loop thread runs Python code. Its first job lowers the process's
switch interval to ``SWITCH_INTERVAL_S`` so a due send waits at most that long. A server whose
streams go to the sender process starts the thread with the first of them, idle: it is there
when a lost process hands it the streams.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import os
import sys
import threading
import time
from collections.abc import Callable

from server.link.stream.stream_process import Deadlines

__all__ = ["Deadlines", "SenderThread", "shared_sender"]

log = logging.getLogger(__name__)

# The GIL switch interval while the sender thread runs: the most a due send waits for a busy
# loop thread to let go of the GIL (CPython's default is 5 ms). The environment's
# SKYHELM_STREAM_SWITCH_INTERVAL_MS overrides it (benches measure the default against it).
SWITCH_INTERVAL_S = float(os.environ.get("SKYHELM_STREAM_SWITCH_INTERVAL_MS", "0.5")) / 1e3

# A job: called with the time it fires at, sends, answers its next deadline or None (done).
# The sender thread's real-time priority (SCHED_FIFO, 1-99; 0 = ordinary scheduling).
SENDER_RT_PRIORITY = int(os.environ.get("SKYHELM_STREAM_RT_PRIORITY", "10"))

# The sender process's (server.link.stream.stream_process): above the threads' and other programs'
# usual real-time work, so only the kernel's own threads (IRQs at 50) come before it.
PROCESS_RT_PRIORITY = int(os.environ.get("SKYHELM_STREAM_PROCESS_RT_PRIORITY", "30"))

Job = Callable[[float], float | None]


class SenderThread:
    """Runs jobs at their deadlines on one daemon thread, started at the first job.
    ``threaded=False`` starts none: whoever owns it calls run_due (tests, on a fake clock)."""

    def __init__(
        self, clock: Callable[[], float] = time.monotonic, *, threaded: bool = True
    ) -> None:
        self.clock = clock
        self._threaded = threaded
        self._cond = threading.Condition(threading.Lock())
        self._heap: list[tuple[float, int, Job]] = []
        self._order = itertools.count()  # ties keep their order; jobs are never compared
        self._thread: threading.Thread | None = None
        self.jobs_failed = 0

    def at(self, deadline_s: float, job: Job) -> None:
        """Run ``job`` at ``deadline_s`` on the clock (at once when it is past)."""
        with self._cond:
            if not self._heap:
                # a job waits for the GIL at most a switch interval: lowered once work comes
                sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL_S))
            heapq.heappush(self._heap, (deadline_s, next(self._order), job))
            if self._heap[0][2] is job:
                self._cond.notify()
            self._start()

    def start(self) -> None:
        """Start the thread now, idle until a job comes: the first job (a stream taken over
        from a lost process) then needs no new thread, which would first wait for a core as
        an ordinary one before it raised its priority."""
        with self._cond:
            self._start()

    @property
    def native_id(self) -> int | None:
        """The OS's id of the running thread (None before it starts)."""
        thread = self._thread
        return thread.native_id if thread is not None and thread.is_alive() else None

    def pending(self) -> int:
        with self._cond:
            return len(self._heap)

    def run_due(self, now_s: float) -> float | None:
        """Run every job due by ``now_s`` and reschedule those that go on; answers the next
        deadline (None: nothing left). The thread's body; tests call it on a fake clock."""
        due: list[Job] = []
        with self._cond:
            while self._heap and self._heap[0][0] <= now_s:
                due.append(heapq.heappop(self._heap)[2])
        for job in due:
            try:
                deadline_s = job(now_s)
            except Exception:
                # one stream's failure must not stop every other stream of the process
                self.jobs_failed += 1
                log.exception("setpoint stream job failed; it stops")
                continue
            if deadline_s is not None:
                with self._cond:
                    heapq.heappush(self._heap, (deadline_s, next(self._order), job))
        with self._cond:
            return self._heap[0][0] if self._heap else None

    def _start(self) -> None:
        """The thread, unless it runs already or the owner runs the jobs (under _cond)."""
        if self._thread is not None or not self._threaded:
            return
        self._thread = threading.Thread(target=self._run, name="setpoint-sender", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        raise_priority()
        while True:
            with self._cond:
                while not self._heap:
                    self._cond.wait()
                wait_s = self._heap[0][0] - self.clock()
                if wait_s > 0:
                    # woken early by an earlier job, or on time: look again either way
                    self._cond.wait(wait_s)
                    continue
            self.run_due(self.clock())


def raise_priority() -> None:
    """Ask the OS to run this thread (Linux: the calling thread only) before ordinary ones
    when its deadline comes (SCHED_FIFO at SENDER_RT_PRIORITY): on a machine whose cores
    are busy (the vehicles' simulators, other servers) a woken sender otherwise waits for a
    time slice. It sleeps between sends, so it takes little. Without the privilege
    (CAP_SYS_NICE) it runs as an ordinary thread and says so once. Also the threads that
    notice a lost sender process, whose streams wait on them."""
    if SENDER_RT_PRIORITY <= 0 or not hasattr(os, "sched_setscheduler"):
        return
    # reset on fork: a thread or process this one starts (a new sender process and its
    # threads) runs at ordinary priority, not at this one's
    policy = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
    try:
        os.sched_setscheduler(0, policy, os.sched_param(SENDER_RT_PRIORITY))
    except OSError as exc:
        log.info("setpoint sender runs at normal priority (no real-time scheduling: %s)", exc)


_shared: SenderThread | None = None
_shared_lock = threading.Lock()


def shared_sender() -> SenderThread:
    """The process's sender thread (one for every link and vehicle)."""
    global _shared
    with _shared_lock:
        if _shared is None:
            _shared = SenderThread()
        return _shared
