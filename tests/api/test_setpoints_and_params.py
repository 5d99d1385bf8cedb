"""Setpoint refusals (envelope, what PX4 drops), lease rules over REST, parameters, and a
vehicle that goes silent."""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

import pytest
import pytest_asyncio

from tests.api.conftest import Api, api_for, eventually, sim_cluster

# One simulated quad serves the whole module: these tests refuse things or read, and each
# leaves the vehicle on the ground without a control lease.
pytestmark = pytest.mark.asyncio(loop_scope="module")


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def shared_quad() -> AsyncIterator[Api]:
    async with sim_cluster("quad") as sim, api_for(sim) as api:
        await api.wait_ready()
        yield api


@pytest_asyncio.fixture(loop_scope="module")
async def quad_api(shared_quad: Api) -> AsyncIterator[Api]:
    yield shared_quad
    leases = shared_quad.app.state.api.leases
    lease = leases.current(1)
    if lease is not None:
        leases.release(1, lease.lease_id)
    shared_quad.lease_headers = {}


def velocity(north_m_s: float = 0.0, down_m_s: float = 0.0) -> dict[str, Any]:
    return {"type": "velocity_ned", "north_m_s": north_m_s, "east_m_s": 0.0, "down_m_s": down_m_s}


@pytest.mark.parametrize(
    ("setpoint", "field", "limit"),
    [
        ({"type": "position_ned", "north_m": 0, "east_m": 0, "down_m": -150}, "max_alt_rel_m", 120),
        (
            {"type": "position_ned", "north_m": 600, "east_m": 0, "down_m": -5},
            "max_distance_m",
            500,
        ),
        (velocity(north_m_s=13.0), "max_speed_xy_m_s", 12),
        (velocity(down_m_s=6.0), "max_speed_z_m_s", 5),
        ({"type": "offset_ned", "north_m": 0, "east_m": 0, "down_m": -130}, "max_alt_rel_m", 120),
    ],
)
async def test_setpoint_outside_envelope_is_422_with_the_limit(
    quad_api: Api, setpoint: dict[str, Any], field: str, limit: float
) -> None:
    await quad_api.take_control()
    response = await quad_api.control("setpoint", setpoint)
    assert response.status_code == 422, response.text
    detail = response.json()["detail"]
    assert detail["field"] == field
    assert detail["limit"] == limit
    assert "envelope" in detail["reason"]
    assert (await quad_api.state())["stream"]["active"] is False


async def test_envelope_comes_from_settings() -> None:
    async with sim_cluster("quad") as sim, api_for(sim, max_speed_xy_m_s=3.0) as api:
        await api.take_control()
        refused = await api.control("setpoint", velocity(north_m_s=4.0))
        assert refused.status_code == 422
        assert refused.json()["detail"]["limit"] == 3.0
        accepted = await api.control("setpoint", velocity(north_m_s=2.0))
        assert accepted.status_code == 200, accepted.text


async def test_takeoff_above_the_envelope_is_422(quad_api: Api) -> None:
    await quad_api.take_control()
    response = await quad_api.control("takeoff", {"altitude_m": 500.0})
    assert response.status_code == 422
    assert response.json()["detail"] == {
        "reason": "takeoff altitude above the envelope",
        "field": "altitude_m",
        "limit": 120.0,
    }


async def test_frame_px4_does_not_support_is_refused_with_px4_words(quad_api: Api) -> None:
    await quad_api.take_control()
    response = await quad_api.control(
        "setpoint", {"type": "raw_local", "frame": 7, "type_mask": 0b110111111000, "x": 1.0}
    )
    assert response.status_code == 422, response.text
    assert response.json()["detail"]["reason"] == "coordinate frame 7 unsupported"
    assert response.json()["detail"]["field"] == "frame"


async def test_setpoint_answer_says_what_went_on_the_wire(quad_api: Api) -> None:
    await quad_api.take_control()
    response = await quad_api.control("setpoint", velocity(north_m_s=1.0))
    assert response.status_code == 200, response.text
    sent = response.json()
    assert sent["message"] == "SET_POSITION_TARGET_LOCAL_NED"
    assert sent["frame"] == 1
    assert sent["type_mask"] & 0b111 == 0b111  # position ignored
    # yaw "keep current" is resolved to the vehicle's yaw before it goes out
    assert {k: v for k, v in sent["setpoint"].items() if not k.startswith("yaw")} == velocity(1.0)
    assert isinstance(sent["setpoint"]["yaw_deg"], float)
    stream = (await quad_api.client.get("/api/v1/vehicles/1/stream")).json()
    assert stream["active"] is True
    assert set(stream) >= {"active", "rate_hz", "interval_p99_ms", "max_gap_ms", "sent"}


async def test_invalid_setpoint_body_is_422_naming_the_field(quad_api: Api) -> None:
    await quad_api.take_control()
    response = await quad_api.control("setpoint", {"type": "velocity_ned", "north_m_s": "fast"})
    assert response.status_code == 422
    locations = {tuple(error["loc"]) for error in response.json()["detail"]}
    assert ("body", "velocity_ned", "north_m_s") in locations
    assert ("body", "velocity_ned", "east_m_s") in locations
    unknown = await quad_api.control("setpoint", {"type": "warp", "north_m": 1})
    assert unknown.status_code == 422
    bad_mode = await quad_api.control("mode", {"mode": "WARP"})
    assert bad_mode.status_code == 422
    assert "unknown mode" in bad_mode.text


async def test_control_calls_need_the_lease(quad_api: Api) -> None:
    client = quad_api.client
    missing = await client.post("/api/v1/vehicles/1/arm", json={})
    assert missing.status_code == 423
    assert "X-Lease-Id" in missing.json()["detail"]["reason"]
    wrong = await client.post("/api/v1/vehicles/1/arm", json={}, headers={"X-Lease-Id": "nope"})
    assert wrong.status_code == 423
    assert (await quad_api.state())["armed"] is False


async def test_second_pilot_gets_409_until_takeover(quad_api: Api) -> None:
    client = quad_api.client
    first = await client.post("/api/v1/vehicles/1/control", json={"client_name": "alice"})
    assert first.status_code == 200
    second = await client.post("/api/v1/vehicles/1/control", json={"client_name": "bob"})
    assert second.status_code == 409
    assert second.json()["detail"]["holder"] == "pilot · alice"
    takeover = await client.post(
        "/api/v1/vehicles/1/control", json={"client_name": "bob", "takeover": True, "force": True}
    )
    assert takeover.status_code == 200
    old = {"X-Lease-Id": first.json()["lease_id"]}
    assert (await client.post("/api/v1/vehicles/1/hold", headers=old)).status_code == 423
    state = await quad_api.state()
    assert state["lease"]["holder"] == "pilot · bob"


async def test_lease_is_renewed_by_control_calls_and_released_by_delete(quad_api: Api) -> None:
    client = quad_api.client
    headers = await quad_api.take_control()
    renewed = await client.put("/api/v1/vehicles/1/control", headers=headers)
    assert renewed.status_code == 200
    assert renewed.json()["expires_in_s"] > 1.5
    status = (await client.get("/api/v1/vehicles/1/control")).json()
    assert status["holder"] is not None
    assert (await client.delete("/api/v1/vehicles/1/control", headers=headers)).status_code == 204
    after = (await client.get("/api/v1/vehicles/1/control")).json()
    assert after == {
        "holder": None,
        "session": None,
        "since_s": None,
        "expires_in_s": None,
        "ttl_s": None,
        "request": None,
        "holder_pid": None,
        "last_end": after["last_end"],
    }
    assert after["last_end"]["end"] == "released"
    assert after["last_end"]["holder"] == status["holder"]


async def test_unrenewed_lease_lapses_after_ttl() -> None:
    short_lease = {"lease_ttl_s": 0.4, "lease_ttl_min_s": 0.2}
    async with sim_cluster("quad") as sim, api_for(sim, **short_lease) as api:
        headers = await api.take_control()
        await eventually(lambda: _lease_gone(api), 2.0, "the lease to lapse", poll_s=0.05)
        assert (
            await api.client.post("/api/v1/vehicles/1/hold", headers=headers)
        ).status_code == 423


async def _lease_gone(api: Api) -> bool:
    return (await api.client.get("/api/v1/vehicles/1/control")).json()["holder"] is None


async def test_params_round_trip(quad_api: Api) -> None:
    client = quad_api.client
    await quad_api.take_control()
    before = await client.get("/api/v1/vehicles/1/params/MIS_TAKEOFF_ALT")
    assert before.status_code == 200
    assert before.json() == {"name": "MIS_TAKEOFF_ALT", "value": 2.5}
    written = await client.put(
        "/api/v1/vehicles/1/params/MIS_TAKEOFF_ALT",
        json={"value": 4.0},
        headers=quad_api.lease_headers,
    )
    assert written.status_code == 200, written.text
    assert written.json()["value"] == 4.0
    several = await client.get(
        "/api/v1/vehicles/1/params", params={"names": "MIS_TAKEOFF_ALT,COM_OF_LOSS_T"}
    )
    assert several.status_code == 200
    assert several.json()["params"]["MIS_TAKEOFF_ALT"] == 4.0
    assert "COM_OF_LOSS_T" in several.json()["params"]
    integer = await client.get("/api/v1/vehicles/1/params/COM_RC_IN_MODE")
    assert isinstance(integer.json()["value"], int)


async def test_param_metadata_describes_each_parameter_as_the_vehicle_serves_it(
    quad_api: Api,
) -> None:
    answer = await quad_api.client.get("/api/v1/vehicles/1/params/metadata")
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["available"] is True
    velocity = body["parameters"]["MPC_XY_VEL_MAX"]
    assert (velocity["min"], velocity["max"], velocity["units"]) == (0.0, 20.0, "m/s")
    assert velocity["default"] == 12.0
    assert velocity["short_desc"] == "Maximum horizontal velocity"
    assert velocity["group"] == "Multicopter Position Control"
    loss_action = body["parameters"]["COM_OBL_RC_ACT"]
    assert {"value": 4, "description": "Land mode"} in loss_action["values"]
    # every parameter the vehicle has is described (they are all PX4's)
    values = (await quad_api.client.get("/api/v1/vehicles/1/params")).json()["params"]
    assert len(values) > 100
    assert set(values) <= set(body["parameters"])


async def test_a_value_outside_the_metadata_range_is_422_with_the_range_and_its_words(
    quad_api: Api,
) -> None:
    await quad_api.take_control()
    url = "/api/v1/vehicles/1/params/MPC_XY_VEL_MAX"
    refused = await quad_api.client.put(url, json={"value": 1000}, headers=quad_api.lease_headers)
    assert refused.status_code == 422, refused.text
    detail = refused.json()["detail"]
    assert detail["field"] == "value"
    assert (detail["minimum"], detail["maximum"], detail["units"]) == (0.0, 20.0, "m/s")
    assert "1000 is outside 0 … 20 m/s (Maximum horizontal velocity)" in detail["reason"]
    assert (await quad_api.client.get(url)).json()["value"] == 12.0  # nothing was sent


async def test_force_sets_a_value_outside_the_range_and_the_echo_is_the_answer(
    quad_api: Api,
) -> None:
    await quad_api.take_control()
    url = "/api/v1/vehicles/1/params/MPC_XY_VEL_MAX"
    headers = quad_api.lease_headers
    try:
        inside = await quad_api.client.put(url, json={"value": 8.5}, headers=headers)
        assert (inside.status_code, inside.json()["value"]) == (200, 8.5)
        forced = await quad_api.client.put(url, json={"value": 25, "force": True}, headers=headers)
        assert forced.status_code == 200, forced.text
        assert forced.json() == {"name": "MPC_XY_VEL_MAX", "value": 25.0}
    finally:
        await quad_api.client.put(url, json={"value": 12.0}, headers=headers)


async def test_a_parameter_name_outside_px4_ids_is_422_naming_the_field(quad_api: Api) -> None:
    for names in ("MIS_TAKEOFF_ALT,\u00a0\uf9b7", "COM)", "A B"):
        answer = await quad_api.client.get("/api/v1/vehicles/1/params", params={"names": names})
        assert answer.status_code == 422, (names, answer.text)
        assert answer.json()["detail"][0]["loc"] == ["query", "names"]


async def test_a_parameter_the_vehicle_lacks_is_404(quad_api: Api) -> None:
    for url in ("/api/v1/vehicles/1/params/NO_SUCH_PARAM",
                "/api/v1/vehicles/1/params?names=MIS_TAKEOFF_ALT,NO_SUCH_PARAM"):  # fmt: skip
        answer = await quad_api.client.get(url)
        assert answer.status_code == 404, answer.text
        assert answer.json()["detail"]["reason"] == "the vehicle has no parameter NO_SUCH_PARAM"


async def test_param_write_needs_the_lease(quad_api: Api) -> None:
    response = await quad_api.client.put(
        "/api/v1/vehicles/1/params/MIS_TAKEOFF_ALT", json={"value": 4.0}
    )
    assert response.status_code == 423


async def test_silent_vehicle_is_503_for_control_and_shown_disconnected() -> None:
    async with sim_cluster("quad") as sim, api_for(sim, silence_timeout_s=0.5) as api:
        headers = await api.take_control()
        # the server knows the vehicle streams: its silence, not its heartbeat, is the bound
        await api.wait_state(
            lambda s: (s["link_quality"] or {}).get("lost_after_s") == 0.5, 5.0,
            "the vehicle judged by its silence")
        await sim.stop()
        await api.wait_state(lambda s: s["connected"] is False, 5.0, "the vehicle to go silent")
        response = await api.client.post("/api/v1/vehicles/1/arm", json={}, headers=headers)
        assert response.status_code == 503
        # how the loss was noticed (it said "no HEARTBEAT" whatever the cause)
        assert response.json()["detail"]["reason"] == (
            "vehicle 1 is not connected: nothing heard for 0.5 s")
        listed = (await api.client.get("/api/v1/vehicles")).json()
        assert listed[0]["connected"] is False
        # and the state says it to whoever reads it later, not only the event and the 503
        state = (await api.client.get("/api/v1/vehicles/1")).json()
        assert state["lost_reason"] == "nothing heard for 0.5 s"
