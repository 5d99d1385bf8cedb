"""The control stages of the REST flight (tests/rest_flight_stages.py): live input and the
deadman, the operator leaving (release, a lapsed TTL), and handover: a second pilot takes
control at once (force), then the first asks for it back and the second grants it, while the
setpoint stream keeps flying the vehicle between holders."""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import httpx

from tests.rest_flight import (
    CLIENT_NAME,
    DEADMAN_TIMEOUT_S,
    LIVE_REPEAT_S,
    Json,
    RestFlight,
    distance_ned,
    in_offboard,
    speed_xy,
    velocity_ned,
)
from tests.waiting import wait_for_blocking

SECOND_NAME = "second pilot"


def live_setpoint_and_deadman(flight: RestFlight) -> None:
    live = velocity_ned(1.5)
    last_sent = time.monotonic()
    for _ in range(int(3.0 / LIVE_REPEAT_S)):  # a key held for 3 s
        flight.expect(
            flight.call("PUT", "setpoint", live, params={"live": "true"}), 200, "live velocity"
        )
        last_sent = time.monotonic()
        time.sleep(LIVE_REPEAT_S)  # the pace of a held key: live input repeats, it never waits
    moving = flight.state()
    assert in_offboard(moving), f"a held live setpoint left OFFBOARD: {moving.get('mode')}"
    assert speed_xy(moving) >= 0.8, f"a held live setpoint must keep flying: {speed_xy(moving):.2f}"
    assert (moving.get("setpoint") or {}).get("north_m_s") == live["north_m_s"], (
        f"braked although the live input kept coming: {moving.get('setpoint')}"
    )

    def braked(state: Json) -> bool:
        setpoint = state.get("setpoint") or {}
        return setpoint.get("type") != "velocity_ned" or not setpoint.get("north_m_s")

    flight.wait_state(
        "the deadman replaced the silent live setpoint", braked, DEADMAN_TIMEOUT_S + 3.0
    )
    braked_after_s = time.monotonic() - last_sent
    assert braked_after_s <= DEADMAN_TIMEOUT_S + 1.0, (
        f"braked {braked_after_s:.2f} s after the last live setpoint, deadman {DEADMAN_TIMEOUT_S} s"
    )
    flight.wait_state(
        "holding a position after braking (< 0.3 m/s, OFFBOARD)",
        lambda s: (
            in_offboard(s)
            and speed_xy(s) < 0.3
            and (s.get("setpoint") or {}).get("type") == "position_ned"
        ),
        10.0,
    )
    status = flight.control()
    assert CLIENT_NAME in (status.get("holder") or ""), f"the deadman ended the lease: {status}"


def lease_released_holds(flight: RestFlight) -> None:
    old = flight.lease_id
    flight.expect(flight.call("DELETE", "control"), 204, "DELETE /control")
    assert flight.control().get("holder") is None, "released but still held"
    _holding_after_operator_loss(flight)
    flight.expect(
        flight.call("PUT", "setpoint", velocity_ned(1.0)),
        423,
        f"a setpoint with the released lease {old}",
    )


def lease_ttl_lapses(flight: RestFlight) -> None:
    ttl_s = 2.0
    lease = flight.expect(
        flight.call("POST", "control", {"client_name": CLIENT_NAME, "ttl_s": ttl_s}, lease=False),
        200,
        "POST /control with ttl_s",
    )
    assert lease["ttl_s"] == ttl_s, f"asked ttl_s {ttl_s}, got {lease}"
    flight.lease_id = lease["lease_id"]
    start = time.monotonic()
    wait_for_blocking(
        f"the {ttl_s} s lease to lapse", lambda: flight.control().get("holder") is None, ttl_s + 1.5
    )
    flight.log(f"  lapsed after {time.monotonic() - start:.1f} s")
    flight.expect(flight.call("PUT", "setpoint", velocity_ned(1.0)), 423, "a lapsed lease")
    _holding_after_operator_loss(flight)
    lease = flight.expect(
        flight.call("POST", "control", {"client_name": CLIENT_NAME}, lease=False),
        200,
        "POST /control again",
    )
    flight.lease_id = lease["lease_id"]


def _holding_after_operator_loss(flight: RestFlight) -> None:
    """on_operator_loss default `hold`: still streaming and in OFFBOARD, a position hold where
    the vehicle was. (Real PX4's estimate wanders by decimetres while it holds: the check is
    that it stays near, not that it stands still.)"""
    where = flight.state()["position_ned"]
    held = flight.wait_state(
        "a position hold in OFFBOARD after the operator left",
        lambda s: in_offboard(s) and (s.get("setpoint") or {}).get("type") == "position_ned",
        5.0,
    )["setpoint"]
    assert distance_ned({"position_ned": where}, held["north_m"], held["east_m"]) < 1.5, (
        f"the hold {held} is not where the vehicle was: {where}"
    )
    flight.hold_state(
        "holding there with the stream on",
        lambda s: (
            in_offboard(s)
            and s.get("setpoint") == held
            and (s.get("stream") or {}).get("active")
            and distance_ned(s, held["north_m"], held["east_m"]) < 2.0
        ),
        2.0,
    )


def handover(flight: RestFlight) -> None:
    flown = flight.state().get("setpoint")
    before = _stream(flight)
    start = time.monotonic()
    taken = flight.expect(
        flight.call(
            "POST",
            "control",
            {"takeover": True, "force": True, "client_name": SECOND_NAME},
            lease=False,
        ),
        200,
        "a forced takeover",
    )
    assert CLIENT_NAME in (taken.get("taken_from") or ""), f"taken_from: {taken}"
    assert taken.get("setpoint") == flown, (
        f"the new holder must start from the setpoint being flown: {taken.get('setpoint')} "
        f"!= {flown}"
    )
    refused = flight.expect(flight.call("PUT", "setpoint", flown), 423, "the old lease after it")
    assert SECOND_NAME in str(refused), f"the 423 must name the new holder: {refused}"
    second_lease = taken["lease_id"]
    _asked_and_granted(flight, second_lease)
    state = flight.state()
    assert in_offboard(state), f"the handovers ended OFFBOARD: {state.get('mode')}"
    after = _stream(flight)
    # Not restarted (the count goes on) and kept sending at least half its rate meanwhile.
    least = before["sent"] + 0.5 * before["rate_hz"] * (time.monotonic() - start)
    assert after["sent"] >= least, (
        f"the stream stopped between holders: before {before}, after {after}"
    )


def _stream(flight: RestFlight) -> Json:
    stream: Json = flight.expect(flight.call("GET", "stream", lease=False), 200, "GET /stream")
    assert stream.get("active"), f"no stream: {stream}"
    return stream


def _asked_and_granted(flight: RestFlight, second_lease: str) -> None:
    """The first pilot asks for control back (the POST waits); the second grants it."""
    with (
        ThreadPoolExecutor(max_workers=1) as pool,
        httpx.Client(base_url=flight.served.api, timeout=30.0) as asker,
    ):
        asked = pool.submit(
            asker.post,
            f"/vehicles/{flight.vehicle_id}/control",
            json={"takeover": True, "client_name": CLIENT_NAME},
            headers=flight.headers(lease=False),
        )
        request = _pending_request(flight)
        flight.log(f"  takeover asked: {request}")
        flight.lease_id = second_lease
        answer = flight.expect(
            flight.call("POST", f"control/requests/{request['request_id']}", {"grant": True}),
            200,
            "the holder grants",
        )
        assert answer.get("grant") is True, answer
        back = asked.result(timeout=30.0)
    flight.log(f"  takeover answered {back.status_code} {back.text[:300]}")
    lease: Json = flight.expect(back, 200, "the asked takeover, granted")
    assert SECOND_NAME in (lease.get("taken_from") or ""), lease
    flight.lease_id = lease["lease_id"]


def _pending_request(flight: RestFlight) -> Json:
    def asked() -> Json | None:
        request: Json | None = flight.control().get("request")
        return request

    request = wait_for_blocking("GET /control to show the takeover request", asked, 5.0)
    assert request is not None
    assert CLIENT_NAME in str(request.get("by")), request
    return request
