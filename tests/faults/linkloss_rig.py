"""The link-loss scenarios' rig: the simulated vehicle behind the fault proxy, the app (or a
real `skyhelm serve`) in front of it, over real UDP on 127.0.0.1.

    sim (api link) <-> [vehicle-facing | FaultProxy | server-facing] <-> SkyHelm

The sim sends to the proxy's vehicle-facing port (its configured remote port, as PX4 does);
the proxy answers the sim at whatever address it last heard it from, so a restarted sim
(a reboot) on a new port is followed by the proxy as a radio would be.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
from pymavlink import mavutil
from websockets.asyncio.client import ClientConnection, connect

from server.link.codec.tlog import iter_tlog
from sim.process.runner import SimCluster
from sim.vehicle import SimVehicle
from tools.faultproxy import FaultProxy

# Real time: the figures (time to detect, COM_OF_LOSS_T) are then in seconds of both clocks.
SIM_SPEED = 1.0


@contextlib.asynccontextmanager
async def proxied_sim(speed: float = SIM_SPEED, seed: int = 13) -> AsyncIterator[Rig]:
    async with FaultProxy(seed=seed) as proxy:
        sim = SimCluster("quad", count=1, speed=speed, api_port=proxy.vehicle_facing_address[1])
        await sim.start()
        rig = Rig(proxy, sim, speed)
        try:
            with sim.fast_forwarded():  # its estimator's start, which no test looks at
                await sim.wait_ready(timeout_s=30.0)
            yield rig
        finally:
            await rig.sim.stop()


@dataclass
class Rig:
    proxy: FaultProxy
    sim: SimCluster
    speed: float

    @property
    def url(self) -> str:
        """What SkyHelm connects to: the proxy's server-facing port."""
        return f"udpout:127.0.0.1:{self.proxy.server_facing_address[1]}"

    @property
    def vehicle(self) -> SimVehicle:
        return self.sim.instances[0].vehicle

    async def reboot(self) -> None:
        """Stop the simulated vehicle and start a new one with the same sysid (a power
        cycle): new process state, boot clock from zero, new source port."""
        await self.sim.stop()
        self.sim = SimCluster(
            "quad", count=1, speed=self.speed, api_port=self.proxy.vehicle_facing_address[1]
        )
        await self.sim.start()


@contextlib.asynccontextmanager
async def ws_logging(url: str) -> AsyncIterator[WsLog]:
    """A telemetry socket on url whose every message is logged in the background."""
    async with connect(url) as ws:
        log = WsLog(ws)
        pump = asyncio.create_task(log.pump())
        try:
            yield log
        finally:
            pump.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await pump


class WsLog:
    """Every message a telemetry socket received, read in the background by pump()."""

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws
        self.messages: list[tuple[float, dict[str, Any]]] = []

    async def pump(self) -> None:
        async for raw in self.ws:
            self.messages.append((time.monotonic(), json.loads(raw)))

    def events(self, kind: str) -> list[dict[str, Any]]:
        return [m["data"] for _, m in self.messages if m.get("type") == "event"
                and m.get("kind") == kind]

    def states(self) -> list[tuple[float, dict[str, Any]]]:
        return [(t, m) for t, m in self.messages if m.get("type") == "state"]


async def rest_state(client: httpx.AsyncClient, vehicle_id: int = 1) -> dict[str, Any]:
    response = await client.get(f"/api/v1/vehicles/{vehicle_id}")
    assert response.status_code == 200, response.text
    result: dict[str, Any] = response.json()
    return result


def read_tlog(log_dir: Path) -> tuple[Path, int, int]:
    """The one .tlog in log_dir, its message count through pymavlink and through
    iter_tlog (whole records)."""
    (path,) = log_dir.glob("*.tlog")
    reader = mavutil.mavlink_connection(str(path), dialect="development")
    count = 0
    while reader.recv_match(blocking=False) is not None:
        count += 1
    reader.close()
    return path, count, sum(1 for _ in iter_tlog(path))
