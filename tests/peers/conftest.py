"""Third-party MAVLink clients (the real MAVSDK server, MAVProxy) against the sim."""

from __future__ import annotations

import asyncio
import socket
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest

from sim.process.runner import SimCluster

# MAVSDK's command timeouts and heartbeat checks run on wall time; these speeds keep
# the sim well inside them while saving wall time in flight phases.
FLIGHT_SPEED = 5.0


def free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


async def first(stream: Any, predicate: Callable[[Any], bool], timeout_s: float) -> Any:
    """The first item of an async telemetry stream that satisfies predicate."""

    async def scan() -> Any:
        async for item in stream:
            if predicate(item):
                return item
        raise AssertionError("stream ended")

    return await asyncio.wait_for(scan(), timeout_s)


MavsdkFactory = Callable[..., Awaitable[tuple[Any, SimCluster]]]


@pytest.fixture
async def mavsdk_drone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> AsyncIterator[MavsdkFactory]:
    """Start a sim and a real mavsdk_server connected to it; both stopped afterwards."""
    # mavsdk_server caches component metadata under the temp directory: keep it in the test's.
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    try:
        import mavsdk_grpc as mavsdk
    except ImportError:  # pragma: no cover - the test extra installs it
        pytest.skip("mavsdk-grpc not installed")
    started: list[tuple[Any, SimCluster]] = []

    async def start(airframe: str = "quad", speed: float = FLIGHT_SPEED) -> tuple[Any, SimCluster]:
        udp_port = free_port(socket.SOCK_DGRAM)
        sim = SimCluster(airframe=airframe, api_port=udp_port, speed=speed)
        await sim.start()
        drone = mavsdk.System(port=free_port(socket.SOCK_STREAM))
        started.append((drone, sim))
        await drone.connect(system_address=f"udpin://127.0.0.1:{udp_port}")
        await first(drone.core.connection_state(), lambda s: s.is_connected, 20.0)
        return drone, sim

    yield start
    for drone, sim in started:
        drone._stop_mavsdk_server()
        await sim.stop()
