"""Pausing the simulated vehicle of a `skyhelm serve` (SIGSTOP its process, SIGCONT after):
the vehicle falls silent as a vehicle whose link is cut, while the server stays up."""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator
from pathlib import Path

from .harness import Serve


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
