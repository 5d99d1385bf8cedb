"""The blocking client against a live server and the simulated quad: control, commands,
waits, setpoints, parameters, typed refusals and the telemetry socket."""

from __future__ import annotations

import pytest

from skyhelm_client import (
    Forbidden,
    InvalidInput,
    NoLease,
    NotFound,
    PositionNed,
    Refused,
    SkyHelm,
    State,
    Unauthorized,
    VelocityNed,
    WaitTimedOut,
)
from tests.client.conftest import pilot_url
from tests.serve_process import Served

ALTITUDE_M = 5.0


def test_flies_with_the_lease_and_every_refusal_is_typed(served: Served) -> None:
    with SkyHelm(pilot_url(served)) as sky, SkyHelm(pilot_url(served)) as other:
        sky.wait_until(lambda s: s.ready_to_fly, timeout_s=30, what="ready to fly")
        with pytest.raises(NoLease) as no_lease:
            sky.arm()
        assert no_lease.value.status == 423
        assert "lease" in no_lease.value.reason

        lease = sky.acquire(ttl_s=30, client_name="sync test")
        assert lease.ttl_s == 30
        assert "sync test" in lease.holder
        with pytest.raises(Refused) as held:
            other.acquire()
        assert held.value.status == 409
        assert held.value.holder == lease.holder
        assert lease.holder in held.value.reason

        assert sky.arm().result == "ACCEPTED"
        assert sky.takeoff(altitude_m=ALTITUDE_M).result == "ACCEPTED"
        state = sky.wait_until(lambda s: s.altitude_m > ALTITUDE_M - 0.5, timeout_s=60)
        assert state.armed

        with pytest.raises(Refused) as refused:  # PX4 does not disarm in the air
            sky.disarm()
        assert refused.value.status == 409
        assert refused.value.result in ("DENIED", "TEMPORARILY_REJECTED", "FAILED")
        assert refused.value.result_code is not None
        assert refused.value.reason

        here = state.position_ned
        started = sky.offboard_start(
            PositionNed(north_m=here.north_m, east_m=here.east_m, down_m=-ALTITUDE_M)
        )
        assert started.result == "ACCEPTED"
        assert sky.state().mode == "OFFBOARD"
        target_north_m = here.north_m + 4.0
        sent = sky.set_setpoint(
            PositionNed(north_m=target_north_m, east_m=here.east_m, down_m=-ALTITUDE_M)
        )
        assert sent["setpoint"]["type"] == "position_ned"
        sky.wait_until(
            lambda s: s.position_ned.horizontal_distance_m(target_north_m, here.east_m) < 0.5,
            timeout_s=60,
        )

        with pytest.raises(InvalidInput) as envelope:
            sky.set_setpoint(VelocityNed(north_m_s=20.0, east_m_s=0.0, down_m_s=0.0))
        assert envelope.value.status == 422
        assert envelope.value.field is not None
        assert envelope.value.limit == 12.0
        with pytest.raises(InvalidInput) as bad_field:
            sky.set_setpoint(
                {"type": "position_ned", "north_m": "far", "east_m": 0.0, "down_m": -5.0}
            )
        assert bad_field.value.field is not None
        assert bad_field.value.field.endswith("north_m")

        with pytest.raises(WaitTimedOut) as waited:
            sky.wait_until(lambda s: s.altitude_m > 1000.0, timeout_s=0.3)
        assert isinstance(waited.value, TimeoutError)

        assert sky.rtl().result == "ACCEPTED"
        landed = sky.wait_until(lambda s: not s.armed, timeout_s=120, what="landing")
        assert landed.landed_state == "ON_GROUND"
        sky.release()
        assert sky.lease is None
        assert sky.control_status()["holder"] is None


def test_parameters_reads_and_the_other_refusals(served: Served) -> None:
    with SkyHelm(pilot_url(served)) as sky:
        assert sky.health()["status"] == "ok"
        assert [vehicle["id"] for vehicle in sky.vehicles()] == [1]
        sky.acquire(ttl_s=1.0)
        with pytest.raises(WaitTimedOut):  # waiting longer than the TTL keeps the lease
            sky.wait_until(lambda s: False, timeout_s=2.5)
        assert sky.lease is not None
        assert sky.control_status()["holder"] == sky.lease.holder
        assert sky.set_param("MIS_TAKEOFF_ALT", 3.5) == pytest.approx(3.5)
        assert sky.param("MIS_TAKEOFF_ALT") == pytest.approx(3.5)
        assert sky.params("MIS_TAKEOFF_ALT", "NAV_RCL_ACT").keys() == {
            "MIS_TAKEOFF_ALT",
            "NAV_RCL_ACT",
        }
    with SkyHelm(served.base_url, token=served.observer_token) as observer:
        assert observer.state().mode
        with pytest.raises(Forbidden) as forbidden:
            observer.acquire()
        assert forbidden.value.status == 403
    with SkyHelm(served.base_url, token="not-the-token") as stranger, pytest.raises(Unauthorized):
        stranger.vehicles()
    with SkyHelm(pilot_url(served), vehicle=9) as nobody, pytest.raises(NotFound) as missing:
        nobody.state()
    assert missing.value.status == 404


def test_telemetry_iterates_states_and_events(served: Served) -> None:
    with SkyHelm(pilot_url(served)) as sky:
        sky.wait_until(lambda s: s.ready_to_fly, timeout_s=30)
        sky.acquire()
        # armed on the ground until the test has looked: the fixture's vehicle waits 10 s of
        # wall time before it disarms itself (COM_DISARM_PRFLT at 8x, set at its start)
        messages = sky.telemetry(rate_hz=20)
        try:
            seen = {next(messages).type}  # the socket is open once a first message came
            sky.arm()
            for message in messages:
                seen.add(message.type)
                if message.state is not None:
                    assert message.vehicle == 1
                if message.type == "event" and message.kind == "armed":
                    assert message.data["data"]["armed"] is True
                    break
        finally:
            messages.close()
        assert "state" in seen
        # a new socket's states reach the armed state (within 5 s: 100 states at 20 Hz; a
        # loaded machine may hold a state back while the vehicle is briefly unheard)
        states = sky.states(rate_hz=20)
        try:
            assert any(state.armed for state, _ in zip(states, range(100), strict=False))
        finally:
            states.close()
        sky.disarm()


def test_ready_to_fly_is_the_arming_checks_verdict(served: Served) -> None:
    """A just-started quad is waited for with ``ready_to_fly``; it arms then. Its state with
    other verdicts: ready only where the server's arm would be taken."""
    with SkyHelm(pilot_url(served)) as sky:
        state = sky.wait_until(lambda s: s.ready_to_fly, timeout_s=30, what="ready to fly")
        sky.acquire(client_name="ready test")
        assert sky.arm().result == "ACCEPTED"
        sky.disarm()
    data = state.as_dict()
    for verdict, ready_to_fly in (("ready", True), ("arm_switches_mode", True),
                                  ("not_ready", False), (None, False)):
        data["arming_checks"] = {**data["arming_checks"], "verdict": verdict}
        assert State(data).ready_to_fly is ready_to_fly, verdict
    data["arming_checks"] = None
    assert State(data).ready_to_fly is False
