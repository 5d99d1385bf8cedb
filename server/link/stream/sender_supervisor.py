"""The setpoint sender process's supervisor: its death or silence is a fault, never a silent stop.

The sender process (server.link.stream.stream_process) sends every frame of the UDP links
handed to it and times their streams. When it dies (its control socket's end of file, its
exit status) or stops answering (its shared heartbeat does not move while streams run; one
still starting has ``READY_TIMEOUT_S``), the supervisor at once:

- takes every link back (each link sends itself again, from the sequence number and signing
  timestamp the process last wrote: the frames go on contiguous and never replayed);
- moves every stream to the sender thread (server.link.stream.stream_thread), with its
  current setpoint and schedule, and runs this server's ordinary threads real-time until a
  new process takes the streams (server.link.stream.fallback_priority): the thread needs
  the interpreter lock, and an ordinary thread holding it must not wait for a core;
- logs the fault once with its cause and tells its listeners (the streams' ``stream``
  events, the state).

Then it starts a new process after a back-off (``RESTART_BACKOFF_S``) and moves the links and
streams back to it (real-time priority again, where allowed). A process that dies within
``STABLE_AFTER_S`` of its start counts as a failed restart; after ``MAX_FAILED_RESTARTS`` in a
row the supervisor gives up: the streams stay on the thread and the status says so.
"""

from __future__ import annotations

import logging
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from server.link.stream.fallback_priority import FallbackPriority
from server.link.stream.stream_thread import raise_priority

log = logging.getLogger(__name__)

# The process writes its heartbeat at least every report period (50 ms). No movement for
# this long while streams run is a stuck process (SIGSTOP, a blocked write)...
STUCK_AFTER_S = 0.15
# ...or for this long when the OS says it is runnable and it ran more than it waited for a
# CPU (a loop that never comes round); one that waited more is starved by a busy machine,
# not stuck, and is left alone (a thread of the server would wait for the same cores).
STARVED_AFTER_S = 0.5
WATCH_PERIOD_S = 0.025
RESTART_BACKOFF_S = (0.25, 1.0, 4.0)
MAX_FAILED_RESTARTS = len(RESTART_BACKOFF_S)
STABLE_AFTER_S = 10.0
# how long close() waits for the watchdog and the restart thread to end
CLOSE_WAIT_S = 1.0
# why the process of a closed supervisor ended: no fault
CLOSED = "its supervisor was closed"
# a restarted process must run its loop this soon, or it failed (it is killed)
READY_TIMEOUT_S = 2.0


class ProcessGone(RuntimeError):
    """The sender process is not running (it could not start, or it died)."""


class Process(Protocol):
    """What the supervisor needs of a sender process (stream_channel.SenderProcess)."""

    pid: int | None
    alive: bool
    started_s: float

    def heartbeat_age_s(self) -> float | None: ...

    def wait_ready(self, timeout_s: float) -> bool: ...

    def kill(self, why: str) -> None: ...

    def wait_ended(self, timeout_s: float) -> bool: ...


class Supervised(Protocol):
    """A link's handover or a stream: told when the process is lost and when one is back."""

    def sender_lost(self, process: object) -> None: ...

    def sender_back(self) -> None: ...

    def streams_in(self, process: object) -> bool: ...


@dataclass(frozen=True)
class SenderStatus:
    """The sender process as the API shows it."""

    running: bool  # a sender process runs now (else every stream is on the thread)
    pid: int | None
    restarts: int  # processes started after a fault
    faults: int
    last_fault: str | None
    last_fault_unix_s: float | None
    gave_up: bool  # restarts kept failing: the streams stay on the thread


class SenderSupervisor:
    """Starts the sender process when first asked, watches it, replaces it after a fault."""

    def __init__(self, start: Callable[[Callable[[Process, str], None]], Process]) -> None:
        self._start = start  # starts a process that calls its argument when it is gone
        # this server's threads, real-time while the sender thread carries the streams
        self.priority = FallbackPriority()
        self._lock = threading.RLock()
        self._process: Process | None = None
        # the process whose loss was handled last (held, so no later process can share its id)
        self._handled: Process | None = None
        self._members: weakref.WeakSet[Supervised] = weakref.WeakSet()
        self._handovers: weakref.WeakSet[Supervised] = weakref.WeakSet()
        self._listeners: list[Callable[[SenderStatus], None]] = []
        self._restarter = Restarter(self._restart)
        self._watchdog: threading.Thread | None = None
        self._closed = threading.Event()
        self.restarts = 0
        self.faults = 0
        self.failed_in_row = 0
        self.gave_up = False
        self.last_fault: str | None = None
        self.last_fault_unix_s: float | None = None

    # -- members --
    def watch_handover(self, handover: Supervised) -> None:
        self._handovers.add(handover)

    def watch(self, member: Supervised) -> None:
        self._members.add(member)

    def on_change(self, listener: Callable[[SenderStatus], None]) -> None:
        self._listeners.append(listener)

    def status(self) -> SenderStatus:
        with self._lock:
            process = self._process
            running = process is not None and process.alive
            return SenderStatus(
                running=running, pid=process.pid if running and process else None,
                restarts=self.restarts, faults=self.faults, last_fault=self.last_fault,
                last_fault_unix_s=self.last_fault_unix_s, gave_up=self.gave_up)

    def current(self) -> Process | None:
        """The running process, if any (never starts one)."""
        with self._lock:
            process = self._process
            return process if process is not None and process.alive else None

    def process(self) -> Process:
        """The running process, started at the first call; ProcessGone while one is being
        replaced or after the supervisor gave up."""
        with self._lock:
            process = self._process
            if process is not None and process.alive:
                return process
            if process is not None or self.gave_up:
                raise ProcessGone(self.last_fault or "the setpoint sender process has ended")
            try:
                self._process = self._start(self.lost)
            except ProcessGone as exc:
                self._fault(f"cannot start: {exc}")
                self.gave_up = True
                raise
            self._start_watchers()
            return self._process

    def close(self) -> None:
        """No restart from now on; the watchdog and the restart thread end, the running
        process is killed (a supervisor of its own for an embedded server or a test: the
        server's own lives as long as its process)."""
        with self._lock:
            self.gave_up = True
            self._closed.set()
            process = self._process
        self._restarter.stop()
        if process is not None and process.alive:
            process.kill(CLOSED)
            # its end is handled (the streams told) before the owner goes on to close them
            process.wait_ended(CLOSE_WAIT_S)
        self.priority.restore()
        for thread in (self._watchdog, self._restarter.thread):
            if thread is not None and thread is not threading.current_thread():
                thread.join(CLOSE_WAIT_S)

    # -- faults --
    def lost(self, process: Process, why: str) -> None:
        """The process died or was killed (any thread; once per process)."""
        with self._lock:
            if process is self._handled or process is not self._process:
                return
            self._handled = process
            closing = self._closed.is_set()
            if closing:
                give_up = True
            else:
                stable = time.monotonic() - process.started_s >= STABLE_AFTER_S
                self.failed_in_row = 1 if stable else self.failed_in_row + 1
                self._fault(why)
                give_up = self.gave_up or self.failed_in_row > MAX_FAILED_RESTARTS
                self.gave_up = give_up
        # the streams first, the words after: every step before the thread sends is a gap
        if give_up:
            self.priority.restore()  # the thread sends from now on: not at the others' cost
        else:
            self.priority.raise_threads()
        for handover in list(self._handovers):
            handover.sender_lost(process)
        for member in list(self._members):
            member.sender_lost(process)
        if closing:  # the owner stops it (a server's end, an embedded one's close)
            log.info("setpoint sender process %s stopped: %s", process.pid, CLOSED)
        else:
            log.error("setpoint sender process %s ended (%s): its links send themselves and "
                      "its streams go on from the sender thread%s", process.pid, why,
                      "; it failed too often and is not started again" if give_up else
                      f"; restarting it in {self._backoff_s():g} s")
        self._tell()
        if not give_up:
            self._restarter.after(self._backoff_s())

    def _fault(self, why: str) -> None:
        self.faults += 1
        self.last_fault = why
        self.last_fault_unix_s = time.time()

    def _backoff_s(self) -> float:
        return RESTART_BACKOFF_S[min(max(self.failed_in_row, 1), len(RESTART_BACKOFF_S)) - 1]

    def _restart(self) -> None:
        # under the lock, so its loss (reported from its reader thread) waits until it is the
        # current process; starting is a fork and exec, milliseconds
        self.priority.raise_spawner()
        with self._lock:
            if self.gave_up:
                self.priority.restore()
                return
            try:
                process = self._process = self._start(self.lost)
            except ProcessGone as exc:
                self._process = None
                self.failed_in_row += 1
                self._fault(f"cannot restart: {exc}")
                self.gave_up = self.failed_in_row > MAX_FAILED_RESTARTS
                if not self.gave_up:
                    self._restarter.after(self._backoff_s())
                else:
                    self.priority.restore()
                self._tell()
                return
            self.restarts += 1
        # the streams move when it runs its loop: until then the thread keeps them going
        if not process.wait_ready(READY_TIMEOUT_S):
            process.kill(f"a restarted process did not start in {READY_TIMEOUT_S:g} s")
            return
        if not process.alive:
            return  # it died at once: its loss was handled
        log.warning("setpoint sender process restarted (pid %s): streams move back to it",
                    process.pid)
        try:
            for handover in list(self._handovers):
                handover.sender_back()
            for member in list(self._members):
                member.sender_back()
        finally:
            self.priority.restore()
        self._tell()

    def _tell(self) -> None:
        status = self.status()
        for listener in list(self._listeners):
            try:
                listener(status)
            except Exception:
                log.exception("setpoint sender: a status listener failed")

    # -- the watchdog: a stuck process --
    def _start_watchers(self) -> None:
        """The watchdog and the restart thread, from the first process on."""
        self._restarter.start()
        if self._watchdog is None:
            self._watchdog = threading.Thread(target=self._watch, name="setpoint-watchdog",
                                              daemon=True)
            self._watchdog.start()

    def _watch(self) -> None:
        # real-time, as the threads that notice a dead process: a stopped one is noticed by
        # this thread alone, and at ordinary priority beside busy cores it looked 250-410 ms
        # after the stop instead of 150
        raise_priority()
        answering: tuple[int | None, tuple[float, float] | None] = (None, None)
        while not self._closed.is_set():
            time.sleep(WATCH_PERIOD_S)  # (a plain sleep: one wake-up, nothing more to run)
            process = self.current()
            if process is None:
                continue
            age_s = process.heartbeat_age_s()
            if age_s is None or age_s < STUCK_AFTER_S:
                # what the process had run and waited for a CPU when last seen answering
                answering = (process.pid, cpu_times_s(process.pid))
                continue
            if not any(member.streams_in(process) for member in list(self._members)):
                continue  # idle: nothing waits on it (it reports once a stream starts)
            if not process.wait_ready(0.0):
                # still starting (a first stream is handed to it at once): its heartbeat is
                # the one the server wrote, and a busy machine took 0.5-0.8 s to run a new
                # interpreter's first loop; a restart waits for it as long
                starting_s = time.monotonic() - process.started_s
                if starting_s >= READY_TIMEOUT_S:
                    process.kill(f"it did not start its loop in {starting_s:.1f} s")
                continue
            state = run_state(process.pid)
            used = cpu_used_s(answering[1] if answering[0] == process.pid else None,
                              cpu_times_s(process.pid))
            starved = used is not None and used[1] > used[0]  # waited more than it ran
            if state == "R" and (age_s < STARVED_AFTER_S or starved):
                continue  # a busy machine: a thread of the server would wait for a CPU too
            if (process.heartbeat_age_s() or 0.0) < STUCK_AFTER_S:
                continue  # it went round meanwhile: this thread was the one kept waiting
            said = "" if used is None else (
                f"; since it last answered it ran {used[0] * 1000:.0f} ms and waited "
                f"{used[1] * 1000:.0f} ms for a CPU")
            process.kill(f"stopped answering: no heartbeat for {age_s * 1000:.0f} ms "
                         f"(process state {state or '?'}{said})")


class Restarter:
    """The thread that starts a new sender process after the back-off. It exists from the
    first process on and waits: at a loss the supervisor raises this server's threads
    (fallback_priority) and it is one of them. A thread started at the loss would start at
    ordinary priority, and its first steps hold the interpreter lock: taken off its core
    there, it held the sender thread back (a 317 ms gap at the vehicle was seen so)."""

    def __init__(self, run: Callable[[], None]) -> None:
        self._run = run
        self._wake = threading.Condition(threading.Lock())
        self._due_s: float | None = None  # time.monotonic() of the next run
        self._stopped = False
        self.thread: threading.Thread | None = None

    def start(self) -> None:
        with self._wake:
            if self.thread is None and not self._stopped:
                self.thread = threading.Thread(target=self._loop, name="setpoint-restarter",
                                               daemon=True)
                self.thread.start()

    def stop(self) -> None:
        """No run from now on; the thread ends."""
        with self._wake:
            self._stopped = True
            self._wake.notify()

    def after(self, delay_s: float) -> None:
        """Run once, delay_s from now (a later call moves it)."""
        with self._wake:
            self._due_s = time.monotonic() + delay_s
            self._wake.notify()

    @property
    def native_id(self) -> int | None:
        return None if self.thread is None else self.thread.native_id

    def _loop(self) -> None:
        while True:
            with self._wake:
                while not self._stopped and (self._due_s is None
                                             or self._due_s > time.monotonic()):
                    self._wake.wait(None if self._due_s is None else
                                    self._due_s - time.monotonic())
                if self._stopped:
                    return
                self._due_s = None
            try:
                self._run()
            except Exception:
                log.exception("setpoint sender: the restart failed")


def run_state(pid: int | None) -> str | None:
    """The process's state letter from /proc (R running, S sleeping, T stopped...)."""
    if pid is None:
        return None
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[0]


def cpu_times_s(pid: int | None) -> tuple[float, float] | None:
    """(time run on a CPU, time waited on a run queue) of the process, from
    /proc/PID/schedstat; None where the kernel does not keep them."""
    if pid is None:
        return None
    try:
        ran_ns, waited_ns = Path(f"/proc/{pid}/schedstat").read_text().split()[:2]
    except (OSError, ValueError):
        return None
    return int(ran_ns) / 1e9, int(waited_ns) / 1e9


def cpu_used_s(before: tuple[float, float] | None, now: tuple[float, float] | None
               ) -> tuple[float, float] | None:
    """(time run, time waited for a CPU) between two readings of cpu_times_s: what the
    process did since it last answered (a loop that never comes round runs all the while; a
    process the machine does not run waits)."""
    if before is None or now is None:
        return None
    return now[0] - before[0], now[1] - before[1]
