"""OFFBOARD on real PX4 v1.16 SITL while the machine is busy: 8 busy-loop processes per core
at normal priority for the whole hover, and PX4 must never see its offboard setpoints
stop (no offboard-loss failsafe). A relay at real-time priority between SkyHelm and PX4
(tests/px4/stamping_relay.py) timestamps each setpoint as PX4 is about to receive it and
follows PX4's own HEARTBEAT mode, so a blip of failsafe between two state reads is seen
too. Opt-in with `make test-px4`; SKYHELM_PX4_CONTENTION_HOLD_S shortens a smoke run."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.px4.conftest import Px4Sitl
from tests.rest_flight import RestFlight, in_offboard
from tests.rest_flight_stages import run_stage
from tests.serve_process import Served, skyhelm_serve

pytestmark = pytest.mark.px4

HOLD_S = float(os.environ.get("SKYHELM_PX4_CONTENTION_HOLD_S", "60"))
BUSY_PER_CORE = 8
PX4_OFFBOARD_MAIN_MODE = 6  # PX4_CUSTOM_MAIN_MODE_OFFBOARD
# PX4 v1.16's default COM_OF_LOSS_T is 1 s; many users run 0.5 s: no interval may come near
OFFBOARD_LOSS_S = 0.5
PROJECT_ROOT = Path(__file__).resolve().parents[2]


class Relay:
    def __init__(self, sitl: Px4Sitl) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.px4.stamping_relay", sitl.api_host,
             str(sitl.api_port)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=PROJECT_ROOT)
        assert self.proc.stdout is not None
        self.port = int(json.loads(self.proc.stdout.readline())["port"])

    def report(self) -> dict[str, Any]:
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        self.proc.stdin.write("report\n")
        self.proc.stdin.flush()
        return dict(json.loads(self.proc.stdout.readline()))

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


@pytest.fixture(scope="module")
def relay(px4: Px4Sitl) -> Iterator[Relay]:
    proxy = Relay(px4)
    yield proxy
    proxy.close()


@pytest.fixture(scope="module")
def flight(px4: Px4Sitl, relay: Relay, tmp_path_factory: pytest.TempPathFactory
           ) -> Iterator[RestFlight]:
    log_dir = tmp_path_factory.mktemp("px4-contention")
    with skyhelm_serve(log_dir, "--connect", f"udpout:127.0.0.1:{relay.port}",
                       "--no-scene") as served:
        session = RestFlight(served, vehicle_id=px4.sysid)
        yield session
        session.http.close()
        _show_stderr(served)


def _show_stderr(served: Served) -> None:
    text = served.stderr_path.read_text()
    if "setpoint sender" in text:
        print(text[-2000:])


def _offboard(modes: list[list[float]]) -> bool:
    """Whether every HEARTBEAT mode listed is OFFBOARD (and there is one)."""
    return bool(modes) and all(
        (int(mode) >> 16) & 0xFF == PX4_OFFBOARD_MAIN_MODE for _, mode in modes)


def _busy_loops(count: int) -> list[subprocess.Popen[bytes]]:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(count)]


def test_px4_offboard_hover_holds_while_every_core_is_busy(flight: RestFlight, relay: Relay
                                                          ) -> None:
    for stage in ("connected", "take_control", "arm", "takeoff", "offboard_start"):
        run_stage(flight, stage)
    # from PX4's first OFFBOARD HEARTBEAT on (1 Hz: the server may know the mode sooner,
    # from CURRENT_MODE)
    deadline = time.monotonic() + 5.0
    while not _offboard(relay.report()["modes"][-1:]) and time.monotonic() < deadline:
        time.sleep(0.2)
    loops = _busy_loops(BUSY_PER_CORE * (os.cpu_count() or 1))
    try:
        started = time.time()
        flight.hold_state(f"OFFBOARD for {HOLD_S:g} s under {len(loops)} busy loops",
                          in_offboard, HOLD_S)
        seen = relay.report()
    finally:
        for loop in loops:
            loop.kill()
        for loop in loops:
            loop.wait()
    arrivals = [t for t in seen["setpoints"] if t >= started]
    intervals = sorted(b - a for a, b in itertools.pairwise(arrivals))
    rate_hz = flight.state()["stream"]["rate_hz"]
    period_s = 1.0 / rate_hz
    errors = sorted(abs(i - period_s) for i in intervals)
    p50_ms = errors[len(errors) // 2] * 1e3
    p99_ms = errors[min(len(errors) - 1, int(0.99 * len(errors)))] * 1e3
    flight.log(f"  at PX4 over {HOLD_S:g} s under {len(loops)} busy loops: "
               f"{len(arrivals)} setpoints, |interval - period| p50 {p50_ms:.2f} ms, p99 "
               f"{p99_ms:.2f} ms, largest interval {intervals[-1] * 1e3:.1f} ms, gaps over "
               f"100 ms {sum(i > 0.1 for i in intervals)}")
    # the mode PX4 was in when the hover began, then each change it reported
    modes = seen["modes"]
    assert _offboard(modes), f"PX4 left OFFBOARD during the hover: {modes}"
    assert len(arrivals) >= 0.95 * rate_hz * HOLD_S, f"only {len(arrivals)} setpoints"
    assert intervals[-1] < OFFBOARD_LOSS_S / 2, f"a {intervals[-1]:.3f} s gap at PX4"
    run_stage(flight, "rtl")
