"""The pace of a `skyhelm serve`'s simulated vehicle: paused (SIGSTOP its process, SIGCONT
after), the vehicle falls silent as a vehicle whose link is cut while the server stays up;
fast-forwarded (SIGUSR1, SIGUSR2 after: `skyhelm sim --fast-forward-speed`), a set-up
flight (a landing, a take-off) that a test does not look at takes a fraction of its time."""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator
from pathlib import Path

import httpx

from sim.process.cli import FAST_FORWARD, REAL_PACE

from .harness import Serve, ServeClient


def sim_pid(serve: Serve) -> int:
    """The `python -m sim` child of the serve process."""
    assert serve._process is not None
    parent = serve._process.pid
    children = Path(f"/proc/{parent}/task/{parent}/children").read_text().split()
    for child in children:
        cmdline = Path(f"/proc/{child}/cmdline").read_bytes().split(b"\0")
        if b"sim" in cmdline:
            return int(child)
    raise AssertionError(f"no simulated vehicle among the children {children} of {parent}")


@contextlib.contextmanager
def sim_paused(serve: Serve) -> Iterator[int]:
    pid = sim_pid(serve)
    os.kill(pid, signal.SIGSTOP)
    try:
        yield pid
    finally:
        os.kill(pid, signal.SIGCONT)


@contextlib.contextmanager
def fast_forward(server: Serve | httpx.Client) -> Iterator[None]:
    """The block's flight at the sim's fast-forward speed; a client that does not know its
    server (tests/browser/harness.py ServeClient) flies it at the server's own speed."""
    serve = server.serve if isinstance(server, ServeClient) else server
    if not isinstance(serve, Serve):
        yield
        return
    pid = sim_pid(serve)
    os.kill(pid, FAST_FORWARD)
    try:
        yield
    finally:
        with contextlib.suppress(ProcessLookupError):  # a test may have stopped the server
            os.kill(pid, REAL_PACE)
