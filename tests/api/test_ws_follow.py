"""Telemetry sockets opened before their vehicle exists follow it: the first state within
1 s of the vehicle's first frame, again within 1 s after it restarts (boot clock from zero),
and a vehicle with a new system id on the same link shows on the unfiltered socket.

The vehicle is `python -m sim` in a process of its own, as a vehicle is another machine: in
the test's process its 8x physics and streams shared one event loop with the server and
the sockets measured, and on a loaded machine the first state then came 1.04 s after the
first frame (two busy loops beside the suite), the test's own weight."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import subprocess
import sys
import time
from collections.abc import AsyncIterator

from tests.api.conftest import OBSERVER, SIM_SPEED, api_at
from tests.faults.linkloss_rig import WsLog, ws_logging
from tests.serving import uvicorn_serving
from tests.waiting import wait_for

FIRST_STATE_WITHIN_S = 1.0


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
    return port


@contextlib.asynccontextmanager
async def _vehicle(api_local_port: int, instance: int = 0) -> AsyncIterator[None]:
    """`python -m sim`: one quad (sysid instance + 1) sending from ``api_local_port``."""
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sim", "--instance", str(instance), "--speed", repr(SIM_SPEED),
        "--api-port", "0", "--gcs-port", "0", "--gcs-local-port", "0",
        # an instance adds its index to the base port, as PX4 SITL does
        "--api-local-port", str(api_local_port - instance),
        "--ready-json", "--exit-on-stdin-eof",
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
    )
    try:
        assert process.stdout is not None
        ready = await asyncio.wait_for(process.stdout.readline(), 30.0)
        assert b'"ready"' in ready, ready
        yield
    finally:
        if process.returncode is None:
            process.terminate()
        await process.wait()


def _first_state_after(log: WsLog, since: float, vehicle: int) -> float | None:
    times = [t for t, m in log.states() if t >= since and m["vehicle"] == vehicle]
    return min(times) if times else None


async def _state_within(log: WsLog, since: float, vehicle: int, what: str) -> float:
    """Seconds from ``since`` to the socket's first state of ``vehicle`` after it."""
    await wait_for(lambda: _first_state_after(log, since, vehicle) is not None, 10.0, what)
    first = _first_state_after(log, since, vehicle)
    assert first is not None
    return first - since


async def _first_frame_seen(vehicle_known: object, timeout_s: float = 20.0) -> float:
    """When the server's link first knew the vehicle (polled every 5 ms)."""
    deadline = time.monotonic() + timeout_s
    while not vehicle_known():  # type: ignore[operator]
        assert time.monotonic() < deadline, "the vehicle never appeared"
        await asyncio.sleep(0.005)
    return time.monotonic()


async def test_sockets_opened_before_the_vehicle_follow_it_through_restart_and_new_ids() -> None:
    port = _free_udp_port()
    url = f"udpout:127.0.0.1:{port}"
    async with api_at(None, None, connect=[url]) as api, uvicorn_serving(api.app) as host:
        base = f"ws://{host}/api/v1/ws/telemetry?token={OBSERVER}&rate_hz=10"
        registry = api.app.state.api.registry
        async with ws_logging(base) as every, ws_logging(f"{base}&vehicle=1") as one:
            await asyncio.sleep(0.3)
            assert not every.states()
            assert not one.states()
            figures: list[str] = []

            async with _vehicle(port):
                seen = await _first_frame_seen(lambda: registry.get(1) is not None)
                for log, name in ((every, "unfiltered"), (one, "vehicle=1")):
                    delay_s = await _state_within(log, seen, 1, f"{name}: first state")
                    figures.append(f"{name} first {delay_s:.2f} s")
                    assert delay_s < FIRST_STATE_WITHIN_S
                vehicle = registry.get(1)
                # long enough for its restart to show as a boot clock going back
                await wait_for(lambda: (vehicle.reboot_watch.latest_boot_ms or 0) > 20_000,
                               10.0, "20 s of the vehicle's boot clock")
            await wait_for(lambda: not vehicle.connected, 5.0, "the vehicle lost")

            async with _vehicle(port):
                restarted = await _first_frame_seen(lambda: vehicle.connected)
                for log, name in ((every, "unfiltered"), (one, "vehicle=1")):
                    delay_s = await _state_within(log, restarted, 1, f"{name}: after restart")
                    figures.append(f"{name} after restart {delay_s:.2f} s")
                    assert delay_s < FIRST_STATE_WITHIN_S
                await wait_for(lambda: any(m.get("kind") == "reboot" for _, m in one.messages),
                               10.0, "the reboot event on the filtered socket")
            await wait_for(lambda: not vehicle.connected, 5.0, "the vehicle lost again")

            async with _vehicle(port, instance=1):
                seen = await _first_frame_seen(lambda: registry.get(2) is not None)
                delay_s = await _state_within(every, seen, 2, "unfiltered: the new system id")
                figures.append(f"new sysid {delay_s:.2f} s")
                assert delay_s < FIRST_STATE_WITHIN_S
                assert all(m["vehicle"] == 1 for _, m in one.states())
    print("\nfirst state after the vehicle's first frame: " + ", ".join(figures))
