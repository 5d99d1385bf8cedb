"""This server's ordinary threads at real-time priority while its sender thread carries a lost
process's streams.

The sender thread runs at real-time priority (server.link.stream.stream_thread), but it needs
the interpreter lock to send, and the thread holding that lock may be an ordinary one (the web
server's event loop) that the OS has just taken off its core for another program. On a
machine with busy cores the sender thread then waits for the OS to run that thread again:
gaps of 300-450 ms at the vehicle, past PX4's proof of life, were seen that way while the
thread carried the streams. While it does, every ordinary thread of this process runs at
``FALLBACK_PRIORITY`` (SCHED_FIFO, below the sender thread's): whoever holds the lock keeps
its core and hands the lock over at the switch interval. Their own priorities come back once
a new sender process takes the streams, or when the supervisor gives up (the streams then
stay on the thread for good, and this server must not hold the cores that long).

Threads the raised ones start meanwhile start ordinary (SCHED_RESET_ON_FORK), but the thread
that starts the new sender process keeps the raised priority for its children: the fork's
child, and the interpreter it becomes, would otherwise wait for a core among every ordinary
program while the lock stays held (a fork holds it until the child runs its exec), and the new
process would take long to start (800 ms was seen beside busy cores). Putting back means
every thread at ``FALLBACK_PRIORITY``, those it started included.
"""

from __future__ import annotations

import logging
import os
import threading
from pathlib import Path

from server.link.stream.stream_thread import SENDER_RT_PRIORITY

log = logging.getLogger(__name__)

# above every ordinary program, below the sender thread and the threads that watch the
# sender process (SENDER_RT_PRIORITY): they preempt these
FALLBACK_PRIORITY = 1
_RESET_ON_FORK = getattr(os, "SCHED_RESET_ON_FORK", 0)


class FallbackPriority:
    """Raises this process's ordinary threads, and puts them back."""

    def __init__(self, tasks: Path = Path("/proc/self/task")) -> None:
        self._tasks = tasks
        self._lock = threading.Lock()
        self.active = False
        self._refused = False  # the OS refused once: not asked again

    def raise_threads(self) -> int:
        """Raise every thread of this process that runs at ordinary priority; answers how
        many were raised (none where the OS does not allow it)."""
        with self._lock:
            if self.active or not _possible() or self._refused:
                return 0
            self.active = True
            raised = 0
            for tid in thread_ids(self._tasks):
                try:
                    if os.sched_getscheduler(tid) & ~_RESET_ON_FORK != os.SCHED_OTHER:
                        continue  # real-time already (the sender thread, the watchers)
                    os.sched_setscheduler(tid, os.SCHED_FIFO | _RESET_ON_FORK,
                                          os.sched_param(FALLBACK_PRIORITY))
                except ProcessLookupError:
                    continue  # it ended meanwhile
                except OSError as exc:
                    self._refused = True
                    log.info("setpoint sender: this server's threads stay at ordinary priority "
                             "while its thread sends (%s)", exc)
                    break
                raised += 1
            return raised

    def raise_spawner(self) -> None:
        """While raised: this thread too, and what it starts (the new sender process and the
        server's threads that watch it)."""
        with self._lock:
            if not self.active:
                return
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(FALLBACK_PRIORITY))
            except OSError:
                return

    def restore(self) -> None:
        """Every thread of this process at the raised priority back to ordinary."""
        with self._lock:
            for tid in filter(raised, thread_ids(self._tasks)):
                try:
                    os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
                except OSError:
                    continue  # it ended
            self.active = False


def raised(tid: int) -> bool:
    """Whether thread ``tid`` runs at ``FALLBACK_PRIORITY`` (False once it has ended)."""
    try:
        return (os.sched_getscheduler(tid) & ~_RESET_ON_FORK == os.SCHED_FIFO
                and os.sched_getparam(tid).sched_priority == FALLBACK_PRIORITY)
    except OSError:
        return False


def _possible() -> bool:
    return SENDER_RT_PRIORITY > FALLBACK_PRIORITY and hasattr(os, "sched_setscheduler")


def thread_ids(tasks: Path) -> list[int]:
    """The thread ids in a /proc/PID/task directory (none once the process has ended)."""
    try:
        return [int(entry.name) for entry in tasks.iterdir() if entry.name.isdigit()]
    except OSError:
        return []
