"""While the sender thread carries a lost process's streams, this server's ordinary threads
run real-time (SCHED_FIFO at FALLBACK_PRIORITY), so whoever holds the interpreter lock keeps
its core; real-time threads keep their own priority; what the raised threads start starts
ordinary, but for the thread that starts the new sender process; putting back returns every
raised thread, and those it started, to ordinary. The supervisor raises them at a loss and
puts them back when a new process takes the streams, or when it gives up."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from server.link.stream import sender_supervisor
from server.link.stream.fallback_priority import FALLBACK_PRIORITY, FallbackPriority, thread_ids
from tests.link.realtime import may_run_real_time
from tests.link.test_sender_supervisor import Member, _supervisor, closed_supervisors
from tests.waiting import wait_for_blocking

pytestmark = [
    pytest.mark.skipif(not may_run_real_time(), reason="no real-time scheduling here"),
    pytest.mark.usefixtures(closed_supervisors.__name__),
]

_RESET = os.SCHED_RESET_ON_FORK
TASKS = Path("/proc/self/task")


def _policy(tid: int) -> tuple[int, int]:
    return os.sched_getscheduler(tid) & ~_RESET, os.sched_getparam(tid).sched_priority


@contextmanager
def _thread(setup: Callable[[], None] = lambda: None) -> Iterator[int]:
    """A thread that sleeps until the block ends; its native id."""
    ready, done = threading.Event(), threading.Event()
    tid: list[int] = []

    def run() -> None:
        setup()
        tid.append(threading.get_native_id())
        ready.set()
        done.wait()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    ready.wait()
    try:
        yield tid[0]
    finally:
        done.set()
        thread.join()


def _real_time_10() -> None:
    os.sched_setscheduler(0, os.SCHED_FIFO | _RESET, os.sched_param(10))


def test_ordinary_threads_are_raised_and_put_back_real_time_ones_keep_theirs() -> None:
    priority = FallbackPriority()
    with _thread() as ordinary, _thread(_real_time_10) as sender:
        try:
            assert priority.raise_threads() >= 2  # the ordinary one and this one
            assert _policy(ordinary) == (os.SCHED_FIFO, FALLBACK_PRIORITY)
            assert _policy(threading.get_native_id()) == (os.SCHED_FIFO, FALLBACK_PRIORITY)
            assert _policy(sender) == (os.SCHED_FIFO, 10)
            assert priority.raise_threads() == 0  # once
            # a thread a raised one starts meanwhile starts ordinary
            with _thread() as later:
                assert _policy(later) == (os.SCHED_OTHER, 0)
        finally:
            priority.restore()
        assert _policy(ordinary) == (os.SCHED_OTHER, 0)
        assert _policy(threading.get_native_id()) == (os.SCHED_OTHER, 0)
        assert _policy(sender) == (os.SCHED_FIFO, 10)
        assert not priority.active


def test_the_spawner_passes_its_priority_on_and_all_of_it_is_put_back() -> None:
    priority = FallbackPriority()
    started: list[tuple[int, int]] = []

    def spawner() -> None:
        priority.raise_spawner()
        with _thread() as child:  # e.g. the new process's writer thread
            started.append(_policy(child))
            priority.restore()
            started.append(_policy(child))

    priority.raise_spawner()  # not raised: nothing happens
    assert _policy(threading.get_native_id()) == (os.SCHED_OTHER, 0)
    priority.raise_threads()
    thread = threading.Thread(target=spawner)
    thread.start()
    thread.join()
    assert started == [(os.SCHED_FIFO, FALLBACK_PRIORITY), (os.SCHED_OTHER, 0)]
    assert _policy(threading.get_native_id()) == (os.SCHED_OTHER, 0)


@pytest.fixture
def _short_backoff(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sender_supervisor, "RESTART_BACKOFF_S", (0.2, 0.2, 0.2))


@pytest.mark.usefixtures("_short_backoff")
def test_the_supervisor_raises_at_a_loss_and_puts_back_when_a_process_takes_over() -> None:
    sup, started = _supervisor()
    member = Member()
    sup.watch(member)
    first = sup.process()
    with _thread() as loop:
        first.die("killed by SIGKILL")  # type: ignore[attr-defined]
        assert _policy(loop) == (os.SCHED_FIFO, FALLBACK_PRIORITY)  # before the restart
        wait_for_blocking("the restart", lambda: member.back == 1, 2.0, 0.005)
        wait_for_blocking("put back", lambda: not sup.priority.active, 2.0, 0.005)
        assert _policy(loop) == (os.SCHED_OTHER, 0)
        assert _policy(threading.get_native_id()) == (os.SCHED_OTHER, 0)
        assert len(started) == 2


@pytest.mark.usefixtures("_short_backoff")
def test_the_supervisor_puts_back_when_it_gives_up() -> None:
    sup, started = _supervisor()
    sup.watch(member := Member())
    sup.process()
    with _thread() as loop:
        for n in range(sender_supervisor.MAX_FAILED_RESTARTS + 1):
            # started, and the streams handed back to it (the priority put back): killed
            # before, the restart's hand-back could put the threads back after this loss
            wait_for_blocking(
                f"process {n + 1} carrying the streams",
                lambda n=n: len(started) == n + 1 and not sup.priority.active, 2.0, 0.005,
            )
            started[n].die("exit status 1")  # type: ignore[attr-defined]
            if n < sender_supervisor.MAX_FAILED_RESTARTS:
                assert _policy(loop) == (os.SCHED_FIFO, FALLBACK_PRIORITY)
        wait_for_blocking("giving up", lambda: sup.gave_up, 2.0, 0.005)
        time.sleep(0.05)
        assert _policy(loop) == (os.SCHED_OTHER, 0)
        assert not sup.priority.active
    assert len(member.lost) == len(started)


@pytest.mark.usefixtures("_short_backoff")
def test_the_restart_runs_on_a_thread_that_waited_since_the_first_process_raised_with_the_others(
) -> None:
    sup, started = _supervisor()
    sup.watch(member := Member())
    sup.process()
    restarter = sup._restarter.native_id
    assert restarter is not None, "no restart thread while the first process runs"
    before = set(thread_ids(TASKS))
    assert restarter in before
    started[0].die("killed by SIGKILL")  # type: ignore[attr-defined]
    # nothing new in the process at the loss: a thread started now would start ordinary
    assert set(thread_ids(TASKS)) <= before
    assert _policy(restarter) == (os.SCHED_FIFO, FALLBACK_PRIORITY)
    wait_for_blocking("the restart", lambda: member.back == 1, 2.0, 0.005)
    wait_for_blocking("put back", lambda: not sup.priority.active, 2.0, 0.005)
    assert _policy(restarter) == (os.SCHED_OTHER, 0)
    assert len(started) == 2
