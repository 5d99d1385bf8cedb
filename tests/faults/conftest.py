"""Fixtures for fault scenarios: the simulated vehicle behind a FaultProxy, SkyHelm in front
of it (connected to the proxy's server-facing port, as to a radio), and counters of what
really reached the vehicle."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from typing import Any

from sim.process.runner import SimCluster
from tests.api.conftest import Api, api_at
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
    async with api_at(url, sim, client_timeout_s=60.0, appear_within_s=20.0,
                      **overrides) as api:
        yield api
