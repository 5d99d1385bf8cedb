"""Whether this machine lets a thread run at real-time priority (SCHED_FIFO): root, or
CAP_SYS_NICE, or an RLIMIT_RTPRIO; the threads that ask for it run without it otherwise."""

from __future__ import annotations

import os
import threading


def may_run_real_time() -> bool:
    """Asked from a thread of its own, which ends: this one keeps its scheduling."""
    allowed: list[bool] = []

    def probe() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
            allowed.append(True)
        except OSError:
            allowed.append(False)

    thread = threading.Thread(target=probe)
    thread.start()
    thread.join()
    return allowed[0]
