"""The embedded simulated vehicle as a child process (`python -m sim`), so its 250 Hz physics
never competes with the streamer's event loop. The server never imports `sim`: it starts the
process, reads its one ready line, and talks MAVLink to the ports it reports.

Its end, other than by stop(), is a fault: seen at once (a task waits on its exit), logged
once with the cause (its exit status or signal), told to ``on_change`` listeners (the
vehicles' ``process`` event) and shown by ``status()``. It is not restarted: a new one
would listen on other ports, and its vehicles would start over on the ground."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import signal
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from server.link.codec.aio import cancel_and_wait

log = logging.getLogger(__name__)

READY_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 5.0


class SimProcessError(RuntimeError):
    """The simulated vehicle did not start; the message carries what it printed."""


@dataclass(frozen=True)
class SimInstance:
    instance: int
    sysid: int
    api_local_port: int
    gcs_local_port: int

    @property
    def url(self) -> str:
        return f"udpout:127.0.0.1:{self.api_local_port}"


class SimProcess:
    def __init__(
        self, *, airframe: str = "quad", count: int = 1, speed: float = 1.0,
        signing_dir: Path | None = None, processes: int = 0,
    ) -> None:
        self.airframe = airframe
        # `python -m sim --processes`: 0 lets it spread the vehicles (one process per 16)
        self.processes = processes
        self.signing_dir = signing_dir  # where the simulated vehicles keep signing keys
        self.count = count
        self.speed = speed
        self.instances: list[SimInstance] = []
        self._process: asyncio.subprocess.Process | None = None
        self._reader: asyncio.Task[None] | None = None
        self._watcher: asyncio.Task[None] | None = None
        self.faults = 0
        self.last_fault: str | None = None
        self.on_change: list[Callable[[dict[str, Any]], None]] = []

    @property
    def pid(self) -> int | None:
        return self._process.pid if self._process is not None else None

    def command(self) -> list[str]:
        return [
            sys.executable,
            "-m",
            "sim",
            "--airframe",
            self.airframe,
            "--count",
            str(self.count),
            "--processes",
            str(self.processes),
            "--speed",
            repr(self.speed),
            "--ready-json",
            "--exit-on-stdin-eof",
            "--api-port",
            "0",
            "--gcs-port",
            "0",
            "--api-local-port",
            "0",
            "--gcs-local-port",
            "0",
            *(["--signing-dir", str(self.signing_dir)] if self.signing_dir is not None else []),
        ]

    async def start(self) -> list[SimInstance]:
        # stdin stays open as a lifeline: if this process dies, the child sees EOF and exits.
        self._process = await asyncio.create_subprocess_exec(
            *self.command(),
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )
        try:
            ready = await asyncio.wait_for(self._read_ready_line(), READY_TIMEOUT_S)
        except (TimeoutError, SimProcessError) as exc:
            errors = await self._stderr_tail()
            await self.stop()
            raise SimProcessError(f"simulated vehicle did not start: {exc}{errors}") from None
        self.instances = [
            SimInstance(
                instance=int(item["instance"]),
                sysid=int(item["sysid"]),
                api_local_port=int(item["api_local_port"]),
                gcs_local_port=int(item["gcs_local_port"]),
            )
            for item in ready["instances"]
        ]
        self._reader = asyncio.create_task(self._forward_output())
        self._watcher = asyncio.create_task(self._watch(self._process))
        log.info("simulated %s x%d running as pid %s", self.airframe, self.count, self.pid)
        return self.instances

    def status(self) -> dict[str, Any]:
        """The process as the API shows it."""
        process = self._process
        running = process is not None and process.returncode is None
        return {"name": "simulated vehicle", "running": running,
                "pid": process.pid if running and process is not None else None,
                "restarts": 0, "faults": self.faults, "last_fault": self.last_fault,
                "gave_up": self.faults > 0}

    async def _watch(self, process: asyncio.subprocess.Process) -> None:
        """Its end while it should run: a fault, said once with the cause."""
        returncode = await process.wait()
        if process is not self._process:
            return  # stop() ended it
        cause = f"exit status {returncode}"
        if returncode < 0:
            with contextlib.suppress(ValueError):
                cause = f"killed by {signal.Signals(-returncode).name}"
        self.faults += 1
        self.last_fault = cause
        log.error("the simulated vehicle's process %s ended (%s): its vehicles are gone; it is "
                  "not restarted (restart the server to fly it again)", process.pid, cause)
        data = {"process": "simulated vehicle", "running": False, "fault": cause,
                "text": f"simulated vehicle's process ended ({cause})"}
        for listener in list(self.on_change):
            try:
                listener(data)
            except Exception:
                log.exception("a simulated vehicle status listener failed")

    async def _read_ready_line(self) -> dict[str, list[dict[str, int]]]:
        assert self._process is not None
        assert self._process.stdout is not None
        while True:
            line = await self._process.stdout.readline()
            if not line:
                raise SimProcessError(f"exited with code {await self._process.wait()}")
            with contextlib.suppress(ValueError):
                message = json.loads(line)
                if isinstance(message, dict) and message.get("event") == "ready":
                    return message
            log.debug("sim: %s", line.decode(errors="replace").rstrip())

    async def _stderr_tail(self) -> str:
        if self._process is None or self._process.stderr is None:
            return ""
        with contextlib.suppress(TimeoutError):
            data = await asyncio.wait_for(self._process.stderr.read(4000), 1.0)
            text = data.decode(errors="replace").strip()
            return f"\n{text}" if text else ""
        return ""

    async def _forward_output(self) -> None:
        """Keep the pipes drained (a full pipe would stall the child) and log what it says."""
        assert self._process is not None

        async def forward(stream: asyncio.StreamReader | None) -> None:
            while stream is not None and (line := await stream.readline()):
                log.info("sim: %s", line.decode(errors="replace").rstrip())

        await asyncio.gather(forward(self._process.stdout), forward(self._process.stderr))

    async def stop(self) -> None:
        process, self._process = self._process, None
        if process is None:
            return
        if process.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                process.send_signal(signal.SIGTERM)
            try:
                await asyncio.wait_for(process.wait(), STOP_TIMEOUT_S)
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    process.kill()
                await process.wait()
        if process.stdin is not None:
            process.stdin.close()
        await cancel_and_wait(self._reader)
        await cancel_and_wait(self._watcher)
        self._reader = self._watcher = None
        log.info("simulated vehicle stopped (exit code %s)", process.returncode)
