"""Fixtures for fault scenarios: the simulated vehicle behind a FaultProxy, SkyHelm in front
of it (connected to the proxy's server-facing port, as to a radio), and counters of what
really reached the vehicle."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from typing import Any

import httpx

from sim.runner import SimCluster
from tests.api.conftest import Api, app_running, auth, make_settings
from tests.waiting import eventually
from tools.faultproxy import FaultProxy

# MAVLink 2 frames start with 0xFD; the message id is bytes 7..9, little endian.
MAVLINK2_STX = 0xFD


def message_id(frame: bytes) -> int | None:
    """The message id of a MAVLink 2 frame (one frame per datagram, as PX4 and SkyHelm send)."""
    if len(frame) < 10 or frame[0] != MAVLINK2_STX:
        return None
    return int.from_bytes(frame[7:10], "little")


@contextlib.asynccontextmanager
async def vehicle_behind_proxy(
    sim: SimCluster, *, seed: int = 1
) -> AsyncIterator[FaultProxy]:
    """A proxy whose vehicle side is the sim's API port; SkyHelm goes to its server side."""
    async with FaultProxy(vehicle=("127.0.0.1", sim.instances[0].api_local_port),
                          seed=seed) as proxy:
        yield proxy


@contextlib.asynccontextmanager
async def api_through(proxy: FaultProxy, sim: SimCluster, **overrides: Any) -> AsyncIterator[Api]:
    """SkyHelm's app connected through ``proxy``, with a pilot client over ASGI."""
    url = f"udpout:127.0.0.1:{proxy.server_facing_address[1]}"
    async with app_running(make_settings(url, **overrides)) as app:
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(
            transport=transport, base_url="http://testserver", headers=auth(), timeout=60.0
        ) as client:
            api = Api(app, client, sim)

            async def has_vehicle() -> bool:
                return bool((await client.get("/api/v1/vehicles")).json())

            await eventually(has_vehicle, 20.0, "the vehicle to appear through the proxy")
            yield api
