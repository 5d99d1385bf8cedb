"""asyncio helpers of the link layer: the loop's clock and stopping background tasks."""

from __future__ import annotations

import asyncio
import contextlib
import time
from typing import Any


def loop_time_s() -> float:
    """The running event loop's clock (time.monotonic on Linux), which a test can make
    virtual; time.monotonic itself outside a loop."""
    try:
        return asyncio.get_running_loop().time()
    except RuntimeError:
        return time.monotonic()


async def cancel_and_wait(task: asyncio.Task[Any] | None) -> None:
    """Cancel ``task`` and return once it has unwound (its ``finally`` blocks have run)."""
    if task is None:
        return
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
