"""Chromium at nice 0, the priority of the servers, vehicles and other jobs beside it.

chromium_for_tests.sh takes from the tests' Chromium the right to raise its own
priority (run as root it would put its display threads at nice -8). Without that right it
cannot undo its own lowering either: it starts each renderer at nice 5, as for a page in the
background, and could not bring it back to 0 when the page showed, so every page of the
tests ran at nice 5. Beside a busy machine's ordinary jobs a process at nice 5 gets a third
of their share of a core (weight 335 against 1024): the pages drew seconds late while the
vehicles they showed flew on. While a test's Chromium runs, this brings each of its threads
below nice 0 back to 0 (the test process may: it runs as root; nothing else is changed).
Nothing is raised above 0: setpriv keeps Chromium from it, and this only raises what is
below."""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator
from pathlib import Path

from tests.cpu_account import proc_stat

PROC = Path("/proc")
# A renderer started in the background runs at nice 5 until this sees it.
POLL_S = 0.25


class ProcessTable:
    """Each process's parent and whether it is Chromium (its name), read from /proc once per
    process: a poll lists /proc's names and reads only the processes it has not seen. Reading
    every process's stat and every Chromium thread's at each poll took 6.1 ms of CPU on a quiet
    machine (131 processes, 115 Chromium threads), 2.5 % of a core for each browser's worker
    and more in the suite, where there are more of both; this takes 0.5 ms."""

    def __init__(self) -> None:
        self._known: dict[int, tuple[int, bool]] = {}

    def refresh(self) -> None:
        alive = {int(name) for name in os.listdir(PROC) if name.isdigit()}
        for pid in self._known.keys() - alive:
            del self._known[pid]
        for pid in alive - self._known.keys():
            self._read(pid)

    def _read(self, pid: int) -> None:
        found = proc_stat(pid)
        if found is None:  # ended meanwhile
            self._known.pop(pid, None)
        else:
            self._known[pid] = (int(found[1][1]), found[0].startswith("chrom"))

    def chromium_descendants(self, root_pid: int) -> list[int]:
        """A descendant not Chromium when first seen is read again: it may have become it
        since (the tests' Chromium starts as a script that execs it)."""
        children: dict[int, list[int]] = {}
        for pid, (parent, _) in self._known.items():
            children.setdefault(parent, []).append(pid)
        found, todo = [], list(children.get(root_pid, []))
        while todo:
            pid = todo.pop()
            todo += children.get(pid, [])
            if not self._known[pid][1]:
                self._read(pid)
            if pid in self._known and self._known[pid][1]:
                found.append(pid)
        return found


def chromium_processes_of(root_pid: int) -> list[int]:
    """Every Chromium process descending from ``root_pid`` (its executable's name)."""
    table = ProcessTable()
    table.refresh()
    return table.chromium_descendants(root_pid)


def nice_of_threads(pid: int) -> dict[int, int]:
    """Each thread's nice value."""
    found: dict[int, int] = {}
    try:
        tids = [int(name) for name in os.listdir(PROC / str(pid) / "task")]
    except OSError:
        return found
    for tid in tids:
        with contextlib.suppress(OSError):  # a thread that ended meanwhile
            found[tid] = os.getpriority(os.PRIO_PROCESS, tid)
    return found


def raise_to_ordinary(root_pid: int, table: ProcessTable) -> int:
    """Brings every thread of ``root_pid``'s Chromium descendants that runs below nice 0 to
    0; returns how many it changed. ``table``: the processes as last seen, refreshed here."""
    table.refresh()
    changed = 0
    for pid in table.chromium_descendants(root_pid):
        for tid, nice in nice_of_threads(pid).items():
            if nice > 0:
                with contextlib.suppress(OSError):  # a thread that ended meanwhile
                    os.setpriority(os.PRIO_PROCESS, tid, 0)
                    changed += 1
    return changed


class OrdinaryPriority:
    """While entered at least once: a thread that keeps this process's Chromium at nice 0."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._users = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _run(self, stop: threading.Event) -> None:
        table = ProcessTable()
        while not stop.wait(POLL_S):
            raise_to_ordinary(os.getpid(), table)

    @contextlib.contextmanager
    def held(self) -> Iterator[None]:
        if os.geteuid() != 0:  # only root may raise a priority
            yield
            return
        with self._lock:
            self._users += 1
            if self._thread is None:
                self._stop = threading.Event()
                self._thread = threading.Thread(
                    target=self._run, args=(self._stop,), name="chromium-priority", daemon=True
                )
                self._thread.start()
        try:
            yield
        finally:
            with self._lock:
                self._users -= 1
                if self._users == 0 and self._thread is not None:
                    self._stop.set()
                    self._thread = None


ORDINARY_PRIORITY = OrdinaryPriority()
