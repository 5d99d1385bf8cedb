"""The simulated vehicle of a running `skyhelm serve`, from outside: its process (the
`python -m sim` child), and its pace: fast-forward (SIGUSR1) for a set-up flight nobody
looks at, then back to the server's --sim-speed (SIGUSR2; `skyhelm sim --fast-forward-speed`)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

from sim.process.cli import FAST_FORWARD, REAL_PACE


def sim_child_pid(server_pid: int) -> int | None:
    """The `python -m sim` child of a server process; None when it flies no simulated
    vehicle (connected to PX4)."""
    children = Path(f"/proc/{server_pid}/task/{server_pid}/children").read_text().split()
    for child in children:
        with contextlib.suppress(FileNotFoundError):
            cmdline = Path(f"/proc/{child}/cmdline").read_bytes().split(b"\0")
            if b"sim" in cmdline:
                return int(child)
    return None


@contextlib.contextmanager
def fast_forwarded(server_pid: int | None) -> Iterator[None]:
    """The block's flight at the sim's fast-forward speed; a server without a simulated
    vehicle (or none given) flies it as it is."""
    pid = sim_child_pid(server_pid) if server_pid is not None else None
    if pid is None:
        yield
        return
    os.kill(pid, FAST_FORWARD)
    try:
        yield
    finally:
        with contextlib.suppress(ProcessLookupError):  # a test may have stopped the server
            os.kill(pid, REAL_PACE)
