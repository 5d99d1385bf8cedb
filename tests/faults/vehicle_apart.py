"""The simulated vehicle and the relay in front of it in a process of their own.

`skyhelm serve` runs its simulated vehicle in a child process, and a real vehicle is another
machine: the server has its process, and its interpreter lock, to itself. A test that ran
the sim's physics in the server's process would measure how long the server's sender thread
waits for that lock behind the sim, a wait no flight has. So here the sim and the relay run
in a spawned process; the test asks it for what the relay heard and the sim counted.
"""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing
from collections.abc import Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from types import TracebackType

from sim.process.run_loop import FAST_FORWARD_SPEED
from sim.process.runner import SimCluster
from tests.faults.sender_relay import Heard, SenderRelay

READY_TIMEOUT_S = 60.0
# what the test may ask of the sim's pace: a set-up flight fast-forward, then real time
PACES = {"fast": FAST_FORWARD_SPEED, "real": 1.0}
STOP_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class Report:
    """What the relay heard and the sim counted, up to the moment it was asked."""

    heard: list[Heard]
    modes: list[tuple[float, int]]  # (unix s, custom_mode) of each HEARTBEAT of the vehicle
    mode_changes: int  # the sim's count of its mode changes, every one
    signing_rejected: int | None  # frames the vehicle refused (None: it has no signing)
    sim_late_s: float  # the most the sim's stepping loop woke up late (a starved process)

    def since(self, unix_s: float, msg_id: int) -> list[Heard]:
        return [h for h in self.heard if h.unix_s >= unix_s and h.msg_id == msg_id]


def _child(conn: Connection, signing_dir: str | None) -> None:
    asyncio.run(_serve(conn, signing_dir))


async def _serve(conn: Connection, signing_dir: str | None) -> None:
    loop = asyncio.get_running_loop()
    keys = Path(signing_dir) if signing_dir is not None else None
    async with SimCluster(airframe="quad", count=1, speed=1.0, signing_dir=keys) as sim:
        with sim.fast_forwarded():  # its estimator's start, which no test looks at
            await sim.wait_ready(timeout_s=30.0)
        instance = sim.instances[0]
        relay = SenderRelay(("127.0.0.1", instance.api_local_port))
        try:
            conn.send(relay.port)
            while True:
                asked = await loop.run_in_executor(None, conn.recv)
                if asked in PACES:
                    sim.pace.set(PACES[asked])
                    continue
                if asked != "report":
                    return
                conn.send(Report(
                    heard=list(relay.heard),
                    modes=list(relay.modes),
                    mode_changes=int(instance.vehicle.commander.mode_changes),
                    signing_rejected=(
                        instance.signing.rejected if instance.signing is not None else None
                    ),
                    sim_late_s=sim.loop_stats.max_lag_s,
                ))
        finally:
            relay.close()


class VehicleApart:
    """The quad in real time behind a relay, in a spawned process; ``relay_port`` is where
    the server sends."""

    def __init__(self, signing_dir: Path | None = None) -> None:
        context = multiprocessing.get_context("spawn")
        self._conn, child_end = context.Pipe()
        self._process = context.Process(
            target=_child, args=(child_end, str(signing_dir) if signing_dir else None),
            name="vehicle-apart", daemon=True,
        )
        self._process.start()
        child_end.close()
        if not self._conn.poll(READY_TIMEOUT_S):
            self.close()
            raise RuntimeError(f"the simulated vehicle did not start in {READY_TIMEOUT_S} s")
        self.relay_port: int = self._conn.recv()

    @contextlib.contextmanager
    def fast_forwarded(self) -> Iterator[None]:
        """The block's flight fast-forward (a climb before what the test times), then real
        time again."""
        self._conn.send("fast")
        try:
            yield
        finally:
            self._conn.send("real")

    def report(self) -> Report:
        self._conn.send("report")
        report: Report = self._conn.recv()
        return report

    async def report_async(self) -> Report:
        return await asyncio.to_thread(self.report)

    def close(self) -> None:
        if self._process.is_alive():
            with contextlib.suppress(OSError):  # the child ended already
                self._conn.send("stop")
            self._process.join(STOP_TIMEOUT_S)
        if self._process.is_alive():
            self._process.kill()
            self._process.join(STOP_TIMEOUT_S)
        self._conn.close()

    def __enter__(self) -> VehicleApart:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()
