"""The Foxglove worker killed (-9) while a client watches and the MCAP records: the server
sees it at once, says so (``/health``, a ``process`` event), starts it again; the client
reconnects through the proxied path and data flows within 2 s; the recording goes on in a
new part, and the crashed part reads back to within 1 s of the kill. (The spare worker that
takes over is awaited first: a server killed in its first seconds starts a new process.)"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import time
from collections.abc import Awaitable, Callable
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader

from server.foxglove import FoxgloveBridge
from server.link import VehicleEvent
from tests.api.conftest import OBSERVER, api_for, sim_cluster
from tests.foxglove.ws_client import foxglove_client
from tests.serving import uvicorn_serving
from tests.waiting import eventually

TOPIC = "/vehicle_1/mavlink/ATTITUDE"
BACK_WITHIN_S = 2.0
MCAP_LOSS_S = 1.0


async def _attitude_after(url: str, after_s: float, within_s: float) -> float:
    """Connect (again and again, while the server is not there) until an ATTITUDE comes;
    answers when it came (Unix s)."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError, Exception):
            async with foxglove_client(url) as client:
                while time.monotonic() < deadline:
                    await client.subscribe(lambda channel: channel["topic"] == TOPIC)
                    if client.received.messages.get(TOPIC):
                        return time.time()
                    client.check()
                    await asyncio.sleep(0.02)
        await asyncio.sleep(0.05)
    raise AssertionError(f"no {TOPIC} within {within_s} s after {after_s}")


def _spare_ready(bridge: FoxgloveBridge) -> Callable[[], Awaitable[bool]]:
    async def ready() -> bool:
        return bridge.spare_ready

    return ready


def _last_message_s(path: Path) -> tuple[int, float]:
    """Messages in a (maybe crashed, footer-less) MCAP file, and the last one's log time."""
    count, last_ns = 0, 0
    with path.open("rb") as file, contextlib.suppress(McapError, EOFError, ValueError):
        for record in StreamReader(file).records:
            if isinstance(record, Message):
                count += 1
                last_ns = max(last_ns, record.log_time)
    return count, last_ns / 1e9


async def test_a_killed_worker_is_restarted_clients_reconnect_and_recording_goes_on(
    tmp_path: Path,
) -> None:
    async with (
        sim_cluster("quad") as sim,
        api_for(sim, foxglove_port=0, mcap=True, log_dir=tmp_path) as api,
        uvicorn_serving(api.app) as host,
    ):
        await api.wait_ready()
        bridge: FoxgloveBridge = api.app.state.foxglove
        events: asyncio.Queue[VehicleEvent] = api.vehicle().subscribe_events()
        url = f"ws://{host}/api/v1/foxglove?token={OBSERVER}"
        await _attitude_after(url, time.time(), 20.0)
        await asyncio.sleep(1.5)  # more than a flush period of recording
        await eventually(_spare_ready(bridge), 30.0, "the spare worker ready")
        status = bridge.status()
        assert status["running"]
        killed_s = time.time()
        os.kill(status["pid"], signal.SIGKILL)
        back_s = await _attitude_after(url, killed_s, 10.0)
        health = (await api.client.get("/api/v1/health")).json()
        found = []
        while not events.empty():
            event = events.get_nowait()
            if event.kind == "process":
                found.append(dict(event.data))
        await asyncio.sleep(1.0)  # the new part records
        paths = list(bridge.mcap_paths)
    print(f"Foxglove worker kill -9: data again {back_s - killed_s:.2f} s after the kill")
    assert back_s - killed_s <= BACK_WITHIN_S
    worker = next(p for p in health["processes"] if p["name"] == "foxglove worker")
    assert worker["running"] is True
    assert worker["restarts"] == 1
    assert "SIGKILL" in worker["last_fault"]
    assert [e["running"] for e in found] == [False, True]
    assert "SIGKILL" in str(found[0]["fault"])

    assert len(paths) == 2
    crashed, resumed = paths
    assert resumed.name == crashed.name.removesuffix(".mcap") + ".1.mcap"
    count, last_s = _last_message_s(crashed)
    print(f"the crashed MCAP part: {count} messages, the last {killed_s - last_s:.2f} s "
          "before the kill")
    assert count > 0
    assert killed_s - last_s <= MCAP_LOSS_S
    with resumed.open("rb") as file:  # closed by the app: a whole file
        resumed_count = sum(1 for _ in make_reader(file).iter_messages())
    assert resumed_count > 0
