"""A page that held control takes it again after a server restart that came back before its
vehicle (a companion computer rebooted while the autopilot was still booting): as soon as the
vehicle is heard, not at the end of a reconnection backoff that has grown meanwhile."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import pytest

from tests.waiting import wait_for_blocking as wait_for

from .flows import take_control
from .harness import REPO, Serve

# Long enough for the page's retries to back off towards their 15 s cap.
VEHICLE_AWAY_S = 10.0
# The vehicle heard, then control: a retry only at the end of the backoff would take up to 15 s.
RETAKE_WITHIN_S = 4.0


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


SIM_PORT = _free_udp_port()
SERVE_ARGS = ["--connect", f"udpout:127.0.0.1:{SIM_PORT}"]


class SimulatedVehicle:
    """`python -m sim` on SIM_PORT, stopped and started again on the same port (as an
    autopilot's link keeps its port across a reboot)."""

    def __init__(self) -> None:
        self._process: subprocess.Popen[str] | None = None

    def start(self) -> None:
        self._process = subprocess.Popen(
            [sys.executable, "-m", "sim", "--ready-json", "--speed", "3", "--api-port", "0",
             "--gcs-port", "0", "--api-local-port", str(SIM_PORT), "--gcs-local-port", "0",
             "--exit-on-stdin-eof"],
            cwd=REPO, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
            text=True,
        )
        assert self._process.stdout is not None
        assert '"ready"' in self._process.stdout.readline()

    def stop(self) -> None:
        process, self._process = self._process, None
        if process is not None:
            process.kill()
            process.wait(5)


@pytest.fixture
def vehicle() -> Iterator[SimulatedVehicle]:
    """Started before the page, which waits for a vehicle to show."""
    sim = SimulatedVehicle()
    sim.start()
    try:
        yield sim
    finally:
        sim.stop()


def test_control_is_taken_again_as_soon_as_the_vehicle_is_back_after_a_server_restart(
    serve: Serve, vehicle: SimulatedVehicle, page: Any
) -> None:
    take_control(page)
    vehicle.stop()
    serve.restart()  # back without its vehicle
    page.wait_for_function(
        "document.getElementById('log').textContent.includes('reconnected')", timeout=60_000)
    time.sleep(VEHICLE_AWAY_S)  # the page's tries are answered "no vehicle 1" meanwhile
    assert page.locator("#release:not(.hidden)").count() == 0
    vehicle.start()
    with serve.client() as api:
        wait_for("the server to hear the vehicle again",
                 lambda: any(v["id"] == 1 and v["connected"] for v in api.get("/vehicles").json()),
                 30.0, every_s=0.05)
    heard = time.monotonic()
    page.wait_for_selector("#release:not(.hidden)", timeout=15_000)
    assert time.monotonic() - heard <= RETAKE_WITHIN_S
