"""The stages of the REST flight (tests/rest_flight.py), in flying order. Each one is what a
user reads in docs/api.md and then checks; the names say what is promised."""

from __future__ import annotations

import time
from collections.abc import Callable

import pymap3d
import pytest

from tests.rest_flight import (
    CLIENT_NAME,
    DEADMAN_TIMEOUT_S,
    LEASE_SURVIVES_WAIT_S,
    MAX_SPEED_XY_M_S,
    TAKEOFF_ALT_M,
    Json,
    RestFlight,
    alt_rel,
    distance_ned,
    in_offboard,
    keep_going,
    position_ned,
    speed_xy,
    velocity_ned,
)
from tests.rest_flight_control import (
    handover,
    lease_released_holds,
    lease_ttl_lapses,
    live_setpoint_and_deadman,
)
from tests.waiting import wait_for_blocking

# PX4 SITL passes its pre-arm checks a few seconds after boot; the sim at once.
ARM_READY_WITHIN_S = 20.0


def connected(flight: RestFlight) -> None:
    health = flight.expect(flight.call("GET", "/health", lease=False), 200, "GET /health")
    assert health.get("status") == "ok", health
    refused = flight.http.get("/vehicles")
    assert refused.status_code == 401, f"no token must be 401, got {refused.status_code}"
    vehicles = wait_for_blocking(
        "a vehicle listed",
        lambda: flight.expect(flight.call("GET", "/vehicles"), 200, "GET /vehicles"),
        30.0,
        every_s=0.5,
    )
    listed = [int(vehicle["id"]) for vehicle in vehicles]
    if flight.vehicle_id is None:
        flight.vehicle_id = listed[0]
    assert flight.vehicle_id in listed, f"vehicle {flight.vehicle_id} not in {vehicles}"
    flight.wait_state(
        "connected with a position and a home",
        lambda s: bool(s.get("connected") and s.get("home") and s.get("global")),
        60.0,
    )


def observer_reads_but_cannot_control(flight: RestFlight) -> None:
    observer = flight.served.observer_token
    flight.expect(flight.call("GET", "", token=observer, lease=False), 200, "observer reads")
    flight.expect(
        flight.call("GET", "control", token=observer, lease=False),
        200,
        "observer sees who controls",
    )
    for method, path, body in (
        ("POST", "control", {}),
        ("POST", "arm", {}),
        ("PUT", "setpoint", velocity_ned(1.0)),
        ("POST", "intents/brake", {}),
    ):
        flight.expect(
            flight.call(method, path, body, token=observer, lease=False),
            403,
            f"observer {method} {path}",
        )


def take_control(flight: RestFlight) -> None:
    lease = flight.expect(
        flight.call("POST", "control", {"client_name": CLIENT_NAME}, lease=False),
        200,
        "POST /control",
    )
    flight.lease_id = lease["lease_id"]
    assert lease["ttl_s"] >= LEASE_SURVIVES_WAIT_S, (
        f"default lease TTL {lease['ttl_s']} s does not outlive a {LEASE_SURVIVES_WAIT_S} s wait"
    )
    status = flight.control()
    assert CLIENT_NAME in (status.get("holder") or ""), f"holder does not name the client: {status}"
    assert (status.get("expires_in_s") or 0.0) > LEASE_SURVIVES_WAIT_S, status
    other = flight.expect(
        flight.call("POST", "control", {}, lease=False),
        409,
        "a second session takes control without takeover",
    )
    assert CLIENT_NAME in str(other), f"the 409 should name the holder: {other}"


def control_needs_the_lease(flight: RestFlight) -> None:
    flight.expect(flight.call("POST", "arm", {}, lease=False), 423, "arm without X-Lease-Id")
    wrong = flight.http.post(
        f"/vehicles/{flight.vehicle_id}/arm",
        json={},
        headers={**flight.headers(lease=False), "X-Lease-Id": "not-the-lease"},
    )
    assert wrong.status_code == 423, f"arm with a wrong lease: {wrong.status_code} {wrong.text}"


def arm(flight: RestFlight) -> None:
    # The state's ready_to_arm (PX4's pre-arm bit) says when arming would pass; PX4 still
    # refuses now and then just after it turned true, so a script retries "not yet" too.
    flight.wait_state("ready to arm", lambda s: bool(s.get("ready_to_arm")), ARM_READY_WITHIN_S)
    start = time.monotonic()
    while (answer := flight.call("POST", "arm", {})).status_code == 409:
        refused = answer.json()
        assert refused.get("result") == "TEMPORARILY_REJECTED", f"arm refused: {refused}"
        assert time.monotonic() - start < ARM_READY_WITHIN_S, f"arm still refused: {refused}"
        time.sleep(1.0)  # the retry interval of a script, as the docs' curl loop does
    armed = flight.expect(answer, 200, "arm")
    assert armed.get("result") == "ACCEPTED", armed
    flight.wait_state("armed", lambda s: bool(s.get("armed")), 5.0)


def takeoff(flight: RestFlight) -> None:
    flight.command("takeoff", {"altitude_m": TAKEOFF_ALT_M})
    flight.wait_state(
        f"climbed to {TAKEOFF_ALT_M} m and the takeoff finished",
        lambda s: alt_rel(s) >= TAKEOFF_ALT_M - 1.0 and s.get("mode") != "TAKEOFF",
        60.0,
    )
    status = flight.control()
    assert CLIENT_NAME in (status.get("holder") or ""), f"the wait lost the lease: {status}"


def offboard_start(flight: RestFlight) -> None:
    here = flight.state()["position_ned"]
    answer = flight.expect(
        flight.call(
            "POST",
            "offboard/start",
            {"setpoint": position_ned(here["north_m"], here["east_m"], -TAKEOFF_ALT_M)},
        ),
        200,
        "offboard/start",
    )
    flight.log(f"  offboard/start answered {answer}")
    state = flight.wait_state("in OFFBOARD", in_offboard, 5.0)
    assert (state.get("stream") or {}).get("active"), f"no stream: {state.get('stream')}"


def position_setpoint(flight: RestFlight) -> None:
    here = flight.state()["position_ned"]
    north_m, east_m = here["north_m"] + 10.0, here["east_m"]
    sent = flight.expect(
        flight.call("PUT", "setpoint", position_ned(north_m, east_m, -TAKEOFF_ALT_M)),
        200,
        "PUT position setpoint",
    )
    for key in ("setpoint", "message", "frame", "type_mask"):
        assert key in sent, f"the setpoint answer lacks {key!r}: {sent}"
    flight.wait_state(
        "reached the position setpoint (1 m, < 0.5 m/s)",
        lambda s: (
            in_offboard(s)
            and distance_ned(s, north_m, east_m) < 1.0
            and speed_xy(s) < 0.5
            and abs(s["position_ned"]["down_m"] + TAKEOFF_ALT_M) < 1.0
        ),
        30.0,
    )


def waiting_keeps_a_position_setpoint(flight: RestFlight) -> None:
    """A script that waits is not a silent live input: nothing brakes its setpoint."""
    target = flight.state().get("setpoint") or {}
    assert target.get("type") == "position_ned", f"not flying a position setpoint: {target}"

    def flying_it(state: Json) -> bool:
        return bool(
            in_offboard(state)
            and state.get("setpoint") == target
            and distance_ned(state, target["north_m"], target["east_m"]) < 1.0
        )

    flight.hold_state(
        f"OFFBOARD at the position setpoint for {3 * DEADMAN_TIMEOUT_S} s without calls",
        flying_it,
        3 * DEADMAN_TIMEOUT_S,
    )


def velocity_setpoint(flight: RestFlight) -> None:
    flight.expect(flight.call("PUT", "setpoint", velocity_ned(2.0)), 200, "PUT velocity 2 m/s")
    flight.wait_state(
        "flying north at 2 m/s (1.5 reached)",
        lambda s: in_offboard(s) and (s.get("velocity_ned") or {}).get("north_m_s", 0) >= 1.5,
        15.0,
    )
    flight.expect(flight.call("PUT", "setpoint", velocity_ned(0.0)), 200, "PUT velocity 0")
    flight.wait_state("stopped (< 0.5 m/s)", lambda s: speed_xy(s) < 0.5, 10.0)


def bad_input_is_422(flight: RestFlight) -> None:
    too_fast = flight.expect(
        flight.call("PUT", "setpoint", velocity_ned(2 * MAX_SPEED_XY_M_S)), 422, "20+ m/s"
    )
    assert "max_speed_xy_m_s" in str(too_fast), f"the 422 names no limit: {too_fast}"
    nan = flight.expect(
        flight.call(
            "PUT",
            "setpoint",
            content='{"type": "velocity_ned", "north_m_s": NaN, "east_m_s": 0, "down_m_s": 0}',
        ),
        422,
        "NaN velocity",
    )
    assert "north_m_s" in str(nan), f"the 422 does not name the NaN field: {nan}"
    flight.expect(
        flight.call("PUT", "setpoint", {"type": "velocity_ned", "north_m_s": 1}),
        422,
        "missing fields",
    )
    flight.expect(
        flight.call("PUT", "setpoint", {"type": "warp", "factor": 9}), 422, "unknown setpoint type"
    )
    flight.expect(
        flight.call("POST", "takeoff", {"altitude_m": 10_000}), 422, "takeoff above the envelope"
    )
    origin = flight.state()["origin"]
    far_lat, far_lon, _ = pymap3d.ned2geodetic(
        50_000.0, 0.0, -TAKEOFF_ALT_M, origin["lat_deg"], origin["lon_deg"], origin["alt_amsl_m"]
    )
    flight.expect(
        flight.call(
            "POST",
            "reposition",
            {"lat_deg": far_lat, "lon_deg": far_lon, "alt_rel_m": TAKEOFF_ALT_M},
        ),
        422,
        "reposition 50 km away",
    )
    state = flight.state()
    setpoint = state.get("setpoint") or {}
    assert in_offboard(state), f"a refused call ended OFFBOARD: {state.get('mode')}"
    assert setpoint.get("type") == "velocity_ned", f"a refusal replaced the setpoint: {setpoint}"
    assert not any(setpoint.get(k) for k in ("north_m_s", "east_m_s", "down_m_s")), (
        f"a refused call changed what is flown: {setpoint}"
    )


def intents(flight: RestFlight) -> None:
    """Moves decided in the server: offset and go-to stay in OFFBOARD, brake stops there."""
    start = flight.state()
    here, start_alt_m = start["position_ned"], alt_rel(start)
    moved = flight.expect(flight.call("POST", "intents/offset", {"north_m": 5.0}), 200, "offset")
    assert moved.get("via") == "setpoint", f"an offset in OFFBOARD stays in OFFBOARD: {moved}"
    flight.wait_state(
        "5 m north by the offset intent (1 m, < 0.5 m/s), still OFFBOARD",
        lambda s: (
            in_offboard(s)
            and distance_ned(s, here["north_m"] + 5.0, here["east_m"]) < 1.0
            and speed_xy(s) < 0.5
        ),
        20.0,
    )
    flight.expect(
        flight.call("PUT", "intents/velocity", {"frame": "ned", "north_m_s": 1.5, "live": False}),
        200,
        "velocity",
    )
    flight.wait_state("flying at 1.5 m/s (1.0 reached)", lambda s: speed_xy(s) >= 1.0, 10.0)
    braked = flight.expect(flight.call("POST", "intents/brake"), 200, "brake")
    assert braked.get("via") == "setpoint", f"brake in OFFBOARD streams a stop: {braked}"
    flight.wait_state(
        "braked and holding in OFFBOARD", lambda s: in_offboard(s) and speed_xy(s) < 0.3, 10.0
    )
    origin = flight.state()["origin"]
    lat, lon, _ = pymap3d.ned2geodetic(
        here["north_m"],
        here["east_m"],
        here["down_m"],
        origin["lat_deg"],
        origin["lon_deg"],
        origin["alt_amsl_m"],
    )
    back = flight.expect(
        flight.call(
            "POST", "intents/goto", {"lat_deg": lat, "lon_deg": lon, "alt_rel_m": start_alt_m}
        ),
        200,
        "goto",
    )
    assert back.get("via") == "setpoint", f"goto in OFFBOARD: {back}"
    flight.wait_state(
        "back where the intents started (1 m, < 0.5 m/s), still OFFBOARD",
        lambda s: (
            in_offboard(s)
            and distance_ned(s, here["north_m"], here["east_m"]) < 1.0
            and speed_xy(s) < 0.5
            and abs(alt_rel(s) - start_alt_m) < 1.0
        ),
        20.0,
    )


def reposition(flight: RestFlight) -> None:
    state = flight.state()
    origin, here = state["origin"], state["position_ned"]
    north_m, east_m = here["north_m"], here["east_m"] + 10.0
    lat, lon, _ = pymap3d.ned2geodetic(
        north_m,
        east_m,
        here["down_m"],
        origin["lat_deg"],
        origin["lon_deg"],
        origin["alt_amsl_m"],
    )
    flight.command("reposition", {"lat_deg": lat, "lon_deg": lon, "alt_rel_m": TAKEOFF_ALT_M})
    flight.wait_state(
        "at the reposition target (1.5 m, < 0.5 m/s), in HOLD",
        lambda s: (
            s.get("mode") == "HOLD" and distance_ned(s, north_m, east_m) < 1.5 and speed_xy(s) < 0.5
        ),
        40.0,
    )


def rtl(flight: RestFlight) -> None:
    assert alt_rel(flight.state()) > 1.0, "not flying: nothing to return from"
    flight.command("rtl")
    flight.wait_state("in RTL", lambda s: s.get("mode") == "RTL", 5.0)
    home = flight.state()["home"]
    with flight.fast_forwarded():  # where it lands is checked, not how long it takes
        landed = flight.wait_state(
            "landed and disarmed",
            lambda s: s.get("landed_state") == "ON_GROUND" and not s.get("armed"),
            150.0,
        )
    off_m = distance_ned(landed, home["north_m"], home["east_m"])
    assert off_m < 2.0, f"landed {off_m:.1f} m from home"


def release_control(flight: RestFlight) -> None:
    flight.expect(flight.call("DELETE", "control"), 204, "DELETE /control")
    assert flight.control().get("holder") is None


STAGES: dict[str, Callable[[RestFlight], None]] = {
    stage.__name__: stage
    for stage in (
        connected,
        observer_reads_but_cannot_control,
        take_control,
        control_needs_the_lease,
        arm,
        takeoff,
        offboard_start,
        position_setpoint,
        waiting_keeps_a_position_setpoint,
        velocity_setpoint,
        bad_input_is_422,
        live_setpoint_and_deadman,
        lease_released_holds,
        lease_ttl_lapses,
        handover,
        intents,
        reposition,
        rtl,
        release_control,
    )
}
STAGE_NAMES = list(STAGES)


def run_stage(flight: RestFlight, name: str) -> None:
    """Run one stage; after a failed stage the later ones are skipped (they need its result)
    unless SKYHELM_FLIGHT_KEEP_GOING=1 asks to record a whole run."""
    if flight.failed_stage and not keep_going():
        pytest.skip(f"stage {flight.failed_stage!r} failed before this one")
    flight.log(f"== stage {name}")
    try:
        STAGES[name](flight)
    except BaseException as error:
        flight.failed_stage = flight.failed_stage or name
        flight.log(f"== stage {name} FAILED: {error}")
        raise
    flight.log(f"== stage {name} passed")
