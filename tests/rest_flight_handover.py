"""The handover stage of the REST flight (tests/rest_flight_stages.py): a second pilot takes
control at once (force), then the first asks for it back and the second grants it, while the
setpoint stream keeps flying the vehicle between holders."""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import httpx

from tests.rest_flight import CLIENT_NAME, Json, RestFlight, in_offboard
from tests.waiting import wait_for_blocking

SECOND_NAME = "second pilot"


def handover(flight: RestFlight) -> None:
    flown = flight.state().get("setpoint")
    before = _stream(flight)
    start = time.monotonic()
    taken = flight.expect(
        flight.call("POST", "control",
                    {"takeover": True, "force": True, "client_name": SECOND_NAME}, lease=False),
        200, "a forced takeover",
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
    with ThreadPoolExecutor(max_workers=1) as pool, httpx.Client(
        base_url=flight.served.api, timeout=30.0
    ) as asker:
        asked = pool.submit(
            asker.post, f"/vehicles/{flight.vehicle_id}/control",
            json={"takeover": True, "client_name": CLIENT_NAME},
            headers=flight.headers(lease=False),
        )
        request = _pending_request(flight)
        flight.log(f"  takeover asked: {request}")
        flight.lease_id = second_lease
        answer = flight.expect(
            flight.call("POST", f"control/requests/{request['request_id']}", {"grant": True}),
            200, "the holder grants",
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
