"""`python -m sim --count N --processes K`: the vehicles spread over K child processes.

Each child is `python -m sim` for a consecutive run of instances with the same base ports
(instance i keeps its ports and sysid, as if one process ran them all). This process waits
for every child's ready line, prints one ready line of its own listing all instances (and
the children's pids), then only supervises: on SIGINT/SIGTERM or the end of its stdin
(--exit-on-stdin-eof) it stops them all; when one child ends on its own it stops the others
and exits 1. Each child's stdin is a pipe from here, so if this process dies they see end
of file and exit too.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import signal
import sys
import threading
from collections.abc import Callable
from typing import Any

READY_TIMEOUT_S = 60.0
STOP_TIMEOUT_S = 5.0

ChildArguments = Callable[[argparse.Namespace, int, int], list[str]]


def split_instances(first: int, count: int, processes: int) -> list[tuple[int, int]]:
    """(first instance, count) of each process: consecutive runs, sizes differing by ≤ 1."""
    runs = []
    start = first
    for k in range(processes):
        size = count // processes + (1 if k < count % processes else 0)
        runs.append((start, size))
        start += size
    return runs


async def _ready_line(proc: asyncio.subprocess.Process) -> dict[str, Any]:
    assert proc.stdout is not None
    while line := await proc.stdout.readline():
        with contextlib.suppress(ValueError):
            message = json.loads(line)
            if isinstance(message, dict) and message.get("event") == "ready":
                return message
    raise RuntimeError(f"sim process {proc.pid} exited with code {await proc.wait()}")


async def _drain(proc: asyncio.subprocess.Process) -> None:
    """Keep a child's stdout read (a full pipe would stall it); it says nothing more."""
    assert proc.stdout is not None
    while await proc.stdout.readline():
        pass


async def _stop_all(children: list[asyncio.subprocess.Process]) -> None:
    _send(children, signal.SIGTERM)
    for proc in children:
        try:
            await asyncio.wait_for(proc.wait(), STOP_TIMEOUT_S)
        except TimeoutError:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()
        if proc.stdin is not None:
            proc.stdin.close()


def _send(children: list[asyncio.subprocess.Process], sig: signal.Signals) -> None:
    for proc in children:
        if proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(sig)


def stop_event(*, exit_on_stdin_eof: bool) -> asyncio.Event:
    """An event set on SIGINT or SIGTERM, and at stdin's end of file when asked."""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    if exit_on_stdin_eof:
        watch_stdin(loop, stop)
    return stop


def watch_stdin(loop: asyncio.AbstractEventLoop, stop: asyncio.Event) -> None:
    """Set ``stop`` when stdin reaches end of file (the parent went away)."""
    def read_until_eof() -> None:
        fd = sys.stdin.fileno()
        while os.read(fd, 4096):
            pass
        loop.call_soon_threadsafe(stop.set)

    threading.Thread(target=read_until_eof, name="stdin-eof", daemon=True).start()


async def run_processes(
    args: argparse.Namespace, processes: int, child_arguments: ChildArguments,
    forwarded: tuple[signal.Signals, ...] = (),
) -> int:
    """Runs the children until asked to stop or one ends; the `forwarded` signals go on to
    every child."""
    stop = stop_event(exit_on_stdin_eof=args.exit_on_stdin_eof)
    children: list[asyncio.subprocess.Process] = []
    for sig in forwarded:
        asyncio.get_running_loop().add_signal_handler(sig, _send, children, sig)
    drains: list[asyncio.Task[None]] = []
    try:
        for first, count in split_instances(args.instance, args.count, processes):
            children.append(await asyncio.create_subprocess_exec(
                sys.executable, "-m", "sim", *child_arguments(args, first, count),
                stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
                # the children's own lines (ports, errors) go where this process's go
            ))
        readies = await _wait_ready(children, stop)
        if readies is None:
            return 0
        instances = sorted(
            (inst for ready in readies for inst in ready["instances"]),
            key=lambda inst: int(inst["instance"]),
        )
        _report(args, instances, [proc.pid for proc in children])
        drains = [asyncio.create_task(_drain(proc)) for proc in children]
        watched: list[asyncio.Future[object]] = [asyncio.ensure_future(stop.wait())]
        watched += [asyncio.ensure_future(proc.wait()) for proc in children]
        await asyncio.wait(watched, return_when=asyncio.FIRST_COMPLETED)
        for waiter in watched:
            waiter.cancel()
        if not stop.is_set():
            dead = [proc for proc in children if proc.returncode is not None]
            print(f"sim: process {dead[0].pid} exited with code {dead[0].returncode}; "
                  "stopping the others", file=sys.stderr, flush=True)
            return 1
        return 0
    finally:
        await _stop_all(children)
        for task in drains:
            task.cancel()


async def _wait_ready(
    children: list[asyncio.subprocess.Process], stop: asyncio.Event
) -> list[dict[str, Any]] | None:
    """Every child's ready line, or None when asked to stop first."""
    gathered = asyncio.ensure_future(asyncio.gather(*(_ready_line(p) for p in children)))
    stopped = asyncio.create_task(stop.wait())
    try:
        done, _ = await asyncio.wait(
            [gathered, stopped], timeout=READY_TIMEOUT_S, return_when=asyncio.FIRST_COMPLETED
        )
        if gathered in done:
            return list(gathered.result())
        if stopped in done:
            return None
        raise RuntimeError(f"sim processes not ready within {READY_TIMEOUT_S:.0f} s")
    finally:
        stopped.cancel()
        if not gathered.done():
            gathered.cancel()
            with contextlib.suppress(asyncio.CancelledError, RuntimeError):
                await gathered


def _report(args: argparse.Namespace, instances: list[dict[str, Any]], pids: list[int]) -> None:
    if args.ready_json:
        print(json.dumps({"event": "ready", "instances": instances, "pids": pids}), flush=True)
    else:
        print(f"sim: {len(instances)} {args.airframe} instances in {len(pids)} processes "
              f"(pids {', '.join(map(str, pids))})", flush=True)
