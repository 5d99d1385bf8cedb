"""kill -9 (or SIGSTOP) of SkyHelm's setpoint sender process while real PX4 v1.16 SITL hovers
in OFFBOARD.

The server's sender thread takes the stream over at once (a stopped process is seen stuck
and killed first) and a restarted process takes it
back: PX4 never leaves OFFBOARD (its HEARTBEAT modes, followed by the real-time stamping
relay, tests/px4/stamping_relay.py), the largest interval between two setpoints as PX4 is
about to receive them stays at or under 150 ms, PX4's own count of our lost frames
(LINK_NODE_STATUS) does not flag the link (no false loss from a sequence jump back), and
the API says what happened. Opt-in with `make test-px4` (SKYHELM_PX4_INSTANCE picks PX4)."""

from __future__ import annotations

import itertools
import os
import signal
import time
from collections.abc import Iterator

import pytest

from tests.px4.conftest import Px4Sitl
from tests.px4.test_px4_stream_contention import Relay, _offboard
from tests.rest_flight import RestFlight
from tests.rest_flight_stages import run_stage
from tests.serve_process import skyhelm_serve

pytestmark = pytest.mark.px4

KILL_GAP_S = 0.150
STOP_GAP_S = 0.250  # the stuck watch (150 ms without a beat), then the kill and the handover
AFTER_S = 6.0  # long enough for PX4's LINK_NODE_STATUS window (5 s) to see any jump


@pytest.fixture(scope="module")
def relay(px4: Px4Sitl) -> Iterator[Relay]:
    proxy = Relay(px4)
    yield proxy
    proxy.close()


@pytest.fixture(scope="module")
def flight(px4: Px4Sitl, relay: Relay, tmp_path_factory: pytest.TempPathFactory
           ) -> Iterator[RestFlight]:
    log_dir = tmp_path_factory.mktemp("px4-sender-kill")
    with skyhelm_serve(log_dir, "--connect", f"udpout:127.0.0.1:{relay.port}",
                       "--no-scene") as served:
        session = RestFlight(served, vehicle_id=px4.sysid)
        yield session
        session.http.close()


def _sender(flight: RestFlight) -> dict[str, object]:
    health = flight.expect(flight.call("GET", "/health", lease=False), 200, "health")
    found: dict[str, object] = next(
        p for p in health["processes"] if p["name"] == "setpoint sender")
    return found


@pytest.mark.parametrize("fault", [signal.SIGKILL, signal.SIGSTOP], ids=["kill-9", "sigstop"])
def test_px4_sender_killed_or_stopped_while_hovering_in_offboard(
    flight: RestFlight, relay: Relay, fault: signal.Signals
) -> None:
    run_stage(flight, "connected")
    flight.wait_state("on the ground, disarmed (after an earlier case's return)",
                      lambda s: s["armed"] is False, 120.0)
    run_stage(flight, "take_control")
    if flight.state()["mode"] == "OFFBOARD":
        # PX4 goes back after a landing to the last mode flown that allows arming: after
        # an earlier case's return that is OFFBOARD, which arms only with a stream
        flight.expect(flight.call("POST", "mode", {"mode": "HOLD"}), 200, "mode HOLD")
    for stage in ("arm", "takeoff", "offboard_start"):
        run_stage(flight, stage)
    deadline = time.monotonic() + 5.0
    while not _offboard(relay.report()["modes"][-1:]) and time.monotonic() < deadline:
        time.sleep(0.2)
    relay.report()  # from here on
    time.sleep(1.0)  # setpoints before the fault, so the interval across it is measured
    sender = _sender(flight)
    assert sender["running"] is True
    restarts = sender["restarts"]
    assert isinstance(restarts, int)
    pid = sender["pid"]
    assert isinstance(pid, int)
    fault_before = flight.state()["stream"]["sender_fault"]  # an earlier case's, or None
    killed_s = time.time()
    os.kill(pid, fault)
    stream = flight.wait_state("the thread or a new process streams",
                               lambda s: s["stream"]["sender_fault"] not in (None, fault_before),
                               2.0)["stream"]
    flight.wait_state("a restarted sender process streams",
                      lambda s: s["stream"]["sender"] == "process"
                      and s["stream"]["sender_restarts"] == restarts + 1, 5.0)
    time.sleep(AFTER_S)
    seen = relay.report()
    state = flight.state()
    after = _sender(flight)
    arrivals = [t for t in seen["setpoints"] if t >= killed_s - 1.0]
    assert arrivals[0] < killed_s - 0.5, "no setpoints seen before the fault"
    largest_s = max(b - a for a, b in itertools.pairwise(arrivals))
    quality = state["link_quality"] or {}
    flight.log(f"  {fault.name} of the sender at PX4: {len(arrivals)} setpoints, largest "
               f"interval {largest_s * 1e3:.1f} ms, PX4's loss_out "
               f"{quality.get('loss_out_pct')} %, modes {seen['modes']}, fault "
               f"{stream['sender_fault']!r}")
    assert _offboard(seen["modes"]), f"PX4 left OFFBOARD: {seen['modes']}"
    gap_s = KILL_GAP_S if fault is signal.SIGKILL else STOP_GAP_S
    assert largest_s <= gap_s, f"a {largest_s * 1e3:.0f} ms gap at PX4"
    cause = "SIGKILL" if fault is signal.SIGKILL else "stopped answering"
    assert cause in str(stream["sender_fault"])
    assert state["stream"]["active"] is True
    assert state["stream"]["sender"] == "process"
    assert after["running"] is True
    assert after["restarts"] == restarts + 1
    assert after["pid"] != pid
    # no false loss from our own handover: PX4 counts every frame of ours it missed
    assert "loss_out" not in quality.get("causes", []), quality
    loss_out = quality.get("loss_out_pct")
    assert loss_out is None or loss_out < 5.0, quality
    run_stage(flight, "rtl")
    run_stage(flight, "release_control")
