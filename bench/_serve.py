"""What several benchmarks share: a `skyhelm serve` process, and a process's CPU from /proc."""

from __future__ import annotations

import asyncio
import contextlib
import os
from collections.abc import AsyncIterator, Mapping, Sequence
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parent.parent
READY_PREFIX = "SkyHelm ready: "
CLK_TCK = os.sysconf("SC_CLK_TCK")


@contextlib.asynccontextmanager
async def served(
    command: Sequence[str], env: Mapping[str, str] | None = None, cwd: Path = PROJECT_ROOT
) -> AsyncIterator[tuple[asyncio.subprocess.Process, str]]:
    """Run ``command`` (a `skyhelm serve` command line) in ``cwd`` until its ready line;
    yields the process and the server's base URL; SIGINT at the end (SIGKILL after 20 s)."""
    proc = await asyncio.create_subprocess_exec(
        *command, stdout=asyncio.subprocess.PIPE, cwd=cwd,
        env=None if env is None else {**os.environ, **env},
    )
    try:
        assert proc.stdout is not None
        line = (await asyncio.wait_for(proc.stdout.readline(), 60)).decode()
        if not line.startswith(READY_PREFIX):
            raise RuntimeError(f"skyhelm serve did not start: {line!r}")
        yield proc, line.split(READY_PREFIX)[1].split("/?token=")[0]
    finally:
        if proc.returncode is None:
            proc.send_signal(2)
            try:
                await asyncio.wait_for(proc.wait(), 20)
            except TimeoutError:
                proc.kill()
                await proc.wait()


def percentile(values: list[float], q: float) -> float | None:
    """Nearest-rank percentile ``q`` (0-100); None for no values."""
    if not values:
        return None
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q / 100 * (len(ordered) - 1)))]


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK  # utime, stime
