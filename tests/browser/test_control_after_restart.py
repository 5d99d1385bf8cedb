"""A page that held control takes it again after a server restart that came back before its
vehicle (a companion computer rebooted while the autopilot's link was still silent): as soon
as the vehicle is heard, not at the end of a reconnection backoff that has grown meanwhile."""

from __future__ import annotations

import json
import os
import signal
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
VEHICLE_SILENT_S = 10.0
# The vehicle heard, then control: a retry only at the end of the backoff would take up to 15 s.
RETAKE_WITHIN_S = 4.0


class SimulatedVehicle:
    """`python -m sim` on an ephemeral port it keeps (as an autopilot's link keeps its port);
    silenced by stopping the process, heard again by continuing it."""

    def __init__(self) -> None:
        self._process = subprocess.Popen(
            [sys.executable, "-m", "sim", "--ready-json", "--speed", "3", "--api-port", "0",
             "--gcs-port", "0", "--api-local-port", "0", "--gcs-local-port", "0",
             "--exit-on-stdin-eof"],
            cwd=REPO, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
            text=True,
        )
        assert self._process.stdout is not None
        ready = json.loads(self._process.stdout.readline())
        self.port: int = ready["instances"][0]["api_local_port"]

    def silence(self) -> None:
        os.kill(self._process.pid, signal.SIGSTOP)

    def resume(self) -> None:
        os.kill(self._process.pid, signal.SIGCONT)

    def stop(self) -> None:
        self.resume()
        self._process.kill()
        self._process.wait(5)


@pytest.fixture(scope="module")
def vehicle() -> Iterator[SimulatedVehicle]:
    sim = SimulatedVehicle()
    try:
        yield sim
    finally:
        sim.stop()


@pytest.fixture(scope="module")
def serve(vehicle: SimulatedVehicle) -> Iterator[Serve]:
    """The server linked to the vehicle's port, as to an autopilot's (no embedded sim)."""
    with Serve(extra_args=["--connect", f"udpout:127.0.0.1:{vehicle.port}"]).running() as server:
        yield server


def test_control_is_taken_again_as_soon_as_the_vehicle_is_back_after_a_server_restart(
    serve: Serve, vehicle: SimulatedVehicle, page: Any
) -> None:
    take_control(page)
    vehicle.silence()
    serve.restart()  # back without its vehicle
    page.wait_for_function(
        "document.getElementById('log').textContent.includes('reconnected')", timeout=60_000)
    time.sleep(VEHICLE_SILENT_S)  # the page's tries are answered "no vehicle 1" meanwhile
    assert page.locator("#release:not(.hidden)").count() == 0
    vehicle.resume()
    with serve.client() as api:
        wait_for("the server to hear the vehicle again",
                 lambda: any(v["id"] == 1 and v["connected"] for v in api.get("/vehicles").json()),
                 30.0, every_s=0.05)
    heard = time.monotonic()
    page.wait_for_selector("#release:not(.hidden)", timeout=15_000)
    assert time.monotonic() - heard <= RETAKE_WITHIN_S
