"""The pace of a `skyhelm serve`'s simulated vehicle: paused (SIGSTOP its process, SIGCONT
after), the vehicle falls silent as a vehicle whose link is cut while the server stays up;
fast-forwarded (tests/sim_pace.py), a set-up flight (a landing, a take-off) that a test
does not look at takes a fraction of its time."""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator

import httpx

from tests.sim_pace import fast_forwarded, sim_child_pid

from .harness import Serve, ServeClient


def sim_pid(serve: Serve) -> int:
    """The `python -m sim` child of the serve process."""
    assert serve._process is not None
    pid = sim_child_pid(serve._process.pid)
    assert pid is not None, f"no simulated vehicle among the children of {serve._process.pid}"
    return pid


@contextlib.contextmanager
def sim_paused(serve: Serve) -> Iterator[int]:
    pid = sim_pid(serve)
    os.kill(pid, signal.SIGSTOP)
    try:
        yield pid
    finally:
        os.kill(pid, signal.SIGCONT)


def fast_forward(server: Serve | httpx.Client) -> contextlib.AbstractContextManager[None]:
    """The block's flight at the sim's fast-forward speed (tests/sim_pace.py); a client that
    does not know its server (tests/browser/harness.py ServeClient) flies it as it is."""
    serve = server.serve if isinstance(server, ServeClient) else server
    process = serve._process if isinstance(serve, Serve) else None
    return fast_forwarded(process.pid if process is not None else None)
