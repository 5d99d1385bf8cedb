"""The setpoint stream on the server's sender process keeps real PX4 v1.16 SITL in OFFBOARD:
take off, start offboard at the current position, then hold for HOLD_S seconds without a
single call from the client; the server's own stream statistics over that time show a
steady stream at its configured rate and no gap."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest

from tests.px4.conftest import Px4Sitl
from tests.rest_flight import RestFlight, in_offboard
from tests.rest_flight_stages import run_stage
from tests.serve_process import Served

pytestmark = pytest.mark.px4

# PX4 leaves OFFBOARD after COM_OF_LOSS_T (1 s) without a setpoint: 30 s of holding it is
# thirty chances to show a stall; SKYHELM_PX4_STREAM_HOLD_S shortens a smoke run.
HOLD_S = float(os.environ.get("SKYHELM_PX4_STREAM_HOLD_S", "30"))


@pytest.fixture(scope="module")
def flight(px4: Px4Sitl, served_px4: Served) -> Iterator[RestFlight]:
    session = RestFlight(served_px4, vehicle_id=px4.sysid)
    yield session
    session.http.close()


def test_px4_stays_in_offboard_on_the_threaded_stream(flight: RestFlight) -> None:
    for stage in ("connected", "take_control", "arm", "takeoff", "offboard_start"):
        run_stage(flight, stage)
    before = flight.state()["stream"]
    flight.hold_state(f"OFFBOARD for {HOLD_S:g} s", in_offboard, HOLD_S)
    after = flight.state()["stream"]
    rate_hz = after["rate_hz"]
    sent = after["sent"] - before["sent"]
    flight.log(f"  stream over the hold: {sent} sent, {after}")
    assert after["active"]
    assert sent >= 0.9 * rate_hz * HOLD_S, f"only {sent} setpoints in {HOLD_S} s: {after}"
    assert after["gaps"] == before["gaps"], f"the stream had gaps: {after}"
    assert after["max_gap_ms"] < 100.0, after
    run_stage(flight, "rtl")
