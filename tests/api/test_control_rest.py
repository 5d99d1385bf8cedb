"""The control model over REST against the simulated vehicle over UDP: the TTL a script asks
for, renaming, asking the holder for control and the answers, the setpoint a new holder starts
from, a stream that never stops between holders, live setpoints and the deadman, and the
audit log across a restart."""

from __future__ import annotations

import asyncio
import gc
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from server.link import StreamStats
from tests.api.conftest import OBSERVER, Api, api_for, auth, sim_cluster
from tests.waiting import eventually, holds_for, wait_for

CONTROL = "/api/v1/vehicles/1/control"
AUDIT = "/api/v1/control/audit"
DEADMAN_S = 0.5
NORTH = {"type": "velocity_ned", "north_m_s": 1.0, "east_m_s": 0.0, "down_m_s": 0.0}
HERE = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -2.0, "yaw_deg": 0.0}


@pytest.fixture
async def api() -> AsyncIterator[Api]:
    async with (
        sim_cluster("quad") as sim,
        api_for(sim, takeover_ask_s=1.0, deadman_timeout_s=DEADMAN_S) as served,
    ):
        await served.wait_ready()
        yield served


async def _take(api: Api, name: str, **body: Any) -> dict[str, str]:
    response = await api.client.post(CONTROL, json={"client_name": name, **body})
    assert response.status_code == 200, response.text
    return {"X-Lease-Id": response.json()["lease_id"]}


async def _audit(
    client: httpx.AsyncClient, headers: dict[str, str] | None = None, **params: Any
) -> list[dict[str, Any]]:
    response = await client.get(AUDIT, params=params, headers=headers)
    assert response.status_code == 200, response.text
    entries: list[dict[str, Any]] = response.json()
    return entries


async def _pending_request(client: httpx.AsyncClient) -> dict[str, Any]:
    async def probe() -> dict[str, Any] | None:
        request: dict[str, Any] | None = (await client.get(CONTROL)).json()["request"]
        return request

    found: dict[str, Any] = await eventually(probe, 5.0, "a takeover request", poll_s=0.01)
    return found


async def test_a_script_asks_its_ttl_within_the_bounds_and_renames_itself(api: Api) -> None:
    client = api.client
    for asked, limit in ((0.5, 1.0), (601.0, 600.0)):
        refused = await client.post(CONTROL, json={"ttl_s": asked})
        assert refused.status_code == 422
        assert refused.json()["detail"]["field"] == "ttl_s"
        assert refused.json()["detail"]["limit"] == limit
    default = await client.post(CONTROL, json={})
    assert default.status_code == 200
    lease = default.json()
    assert lease["ttl_s"] == 120.0
    assert lease["session"] == "rest"
    assert lease["holder"].startswith("pilot · rest ")
    assert (lease["setpoint"], lease["taken_from"]) == (None, None)
    headers = {"X-Lease-Id": lease["lease_id"]}

    renewed = await client.put(
        CONTROL, json={"ttl_s": 30, "client_name": "mapper"}, headers=headers
    )
    assert renewed.status_code == 200
    assert (renewed.json()["ttl_s"], renewed.json()["holder"]) == (30.0, "pilot · mapper")
    status = (await client.get(CONTROL, headers=auth(OBSERVER))).json()
    assert status["holder"] == "pilot · mapper"
    assert status["session"] == "rest"
    assert status["ttl_s"] == 30.0
    assert 29.0 < status["expires_in_s"] <= 30.0
    assert status["since_s"] >= 0.0
    assert status["request"] is None
    too_long = await client.put(CONTROL, json={"ttl_s": 9999}, headers=headers)
    assert too_long.status_code == 422
    actions = [e["data"]["action"] for e in await _audit(client, vehicle=1)]
    assert actions == ["acquired", "renamed"]


async def test_a_granted_takeover_starts_from_the_flown_setpoint_without_a_gap(api: Api) -> None:
    # This process has run hundreds of tests: a full collection of its heap holds the GIL,
    # and so the stream's sender thread, for a few hundred ms. `skyhelm serve` freezes its
    # start-up heap out of the collector's reach; here the collector waits for the test.
    gc.disable()
    try:
        await _takeover_without_a_gap(api)
    finally:
        gc.enable()


async def _takeover_without_a_gap(api: Api) -> None:
    client = api.client
    alice = await _take(api, "alice")
    flown = await client.put("/api/v1/vehicles/1/setpoint", json=HERE, headers=alice)
    assert flown.status_code == 200, flown.text
    vehicle = api.vehicle()
    await wait_for(lambda: vehicle.stream_stats().sent >= 10, 5.0, "the stream to run")

    asking = asyncio.ensure_future(
        client.post(CONTROL, json={"client_name": "bob", "takeover": True})
    )
    request = await _pending_request(client)
    assert request["by"] == "pilot · bob"
    assert 0.0 < request["expires_in_s"] <= 1.0
    answered = await client.post(
        f"{CONTROL}/requests/{request['request_id']}", json={"grant": True}, headers=alice
    )
    assert answered.status_code == 200, answered.text
    assert answered.json() == {
        "request_id": request["request_id"],
        "grant": True,
        "by": "pilot · bob",
    }
    bob = (await asking).json()
    assert bob["holder"] == "pilot · bob"
    assert bob["taken_from"] == "pilot · alice"
    assert bob["setpoint"] == flown.json()["setpoint"]

    sent_at_takeover = vehicle.stream_stats().sent
    await wait_for(
        lambda: vehicle.stream_stats().sent >= sent_at_takeover + 10, 5.0, "the stream to go on"
    )
    _assert_no_gap(vehicle.stream_stats(), vehicle.stream_rate_hz)

    stale = await client.post("/api/v1/vehicles/1/hold", headers=alice)
    assert stale.status_code == 423
    assert stale.json()["detail"]["holder"] == "pilot · bob"
    assert "taken over by pilot · bob" in stale.json()["detail"]["reason"]
    actions = [e["data"]["action"] for e in await _audit(client, vehicle=1)]
    assert actions == [
        "acquired",
        "takeover_requested",
        "takeover_granted",
        "taken_over",
        "acquired",
    ]


def _assert_no_gap(stats: StreamStats, rate_hz: float) -> None:
    """No interval of the stream longer than two periods, across the handover too."""
    assert stats.active
    assert stats.gaps == 0, stats
    assert stats.max_gap_ms is not None
    assert stats.max_gap_ms <= 2 * 1000.0 / rate_hz, stats


async def test_a_denied_or_unanswered_takeover_is_a_409_naming_the_holder(api: Api) -> None:
    client = api.client
    alice = await _take(api, "alice")
    asking = asyncio.ensure_future(
        client.post(CONTROL, json={"client_name": "bob", "takeover": True})
    )
    request = await _pending_request(client)
    deny = {"grant": False}
    answer = await client.post(f"{CONTROL}/requests/{request['request_id']}", json=deny)
    assert answer.status_code == 423  # only the holder answers
    answer = await client.post(
        f"{CONTROL}/requests/{request['request_id']}", json=deny, headers=alice
    )
    assert answer.status_code == 200
    denied = await asking
    assert denied.status_code == 409
    assert denied.json()["detail"] == {
        "reason": "denied by pilot · alice",
        "holder": "pilot · alice",
    }

    unanswered = await client.post(CONTROL, json={"client_name": "bob", "takeover": True})
    assert unanswered.status_code == 409
    assert unanswered.json()["detail"]["reason"] == "pilot · alice did not answer within 1 s"
    late = await client.post(
        f"{CONTROL}/requests/{request['request_id']}", json=deny, headers=alice
    )
    assert late.status_code == 404
    assert (await client.get(CONTROL)).json()["holder"] == "pilot · alice"

    forced = await client.post(
        CONTROL, json={"client_name": "bob", "takeover": True, "force": True}
    )
    assert forced.status_code == 200
    assert forced.json()["taken_from"] == "pilot · alice"
    observer = await client.post(f"{CONTROL}/requests/anything", json=deny, headers=auth(OBSERVER))
    assert observer.status_code == 403


async def test_a_silent_live_setpoint_brakes_and_a_script_setpoint_waits(api: Api) -> None:
    client = api.client
    headers = await _take(api, "keys")
    vehicle = api.vehicle()
    # before the request: the server cannot have it sooner (its answer may come late)
    fed_at = asyncio.get_running_loop().time()
    live = await client.put(
        "/api/v1/vehicles/1/setpoint", params={"live": "true"}, json=NORTH, headers=headers
    )
    assert live.status_code == 200, live.text

    async def braked() -> list[dict[str, Any]]:
        return [e for e in await _audit(client, vehicle=1) if e["kind"] == "deadman"]

    (event,) = await eventually(braked, DEADMAN_S + 2.0, "the deadman to brake", poll_s=0.02)
    assert asyncio.get_running_loop().time() - fed_at >= DEADMAN_S
    assert event["data"]["action"] == "brake"
    assert event["data"]["cause"] == "live_timeout"
    assert event["data"]["ok"] is True
    assert event["data"]["setpoint"]["type"] == "velocity_ned"
    assert event["data"]["setpoint"]["north_m_s"] == 0.0
    assert vehicle.stream_stats().active  # braking is a setpoint, never a stopped stream
    assert (await client.get(CONTROL)).json()["holder"] == "pilot · keys"

    script = await client.put("/api/v1/vehicles/1/setpoint", json=NORTH, headers=headers)
    assert script.status_code == 200
    streamed = vehicle.offboard.setpoint
    await holds_for(
        lambda: vehicle.offboard.setpoint == streamed, 4 * DEADMAN_S, "the script's setpoint"
    )
    assert len(await braked()) == 1


async def test_the_audit_log_survives_a_restart(tmp_path: Path) -> None:
    async with sim_cluster("quad") as sim:
        async with api_for(sim, log_dir=tmp_path) as first:
            headers = await _take(first, "before restart")
            released = await first.client.delete(CONTROL, headers=headers)
            assert released.status_code == 204
        async with api_for(sim, log_dir=tmp_path) as second:
            entries = await _audit(second.client, vehicle=1, limit=10)
            observer_view = await _audit(second.client, auth(OBSERVER), limit=1)
    assert [(e["data"]["action"], e["data"]["previous_holder"]) for e in entries] == [
        ("acquired", None),
        ("released", "pilot · before restart"),
    ]
    assert all(e["kind"] == "control" and e["vehicle"] == 1 for e in entries)
    assert entries[0]["time_unix_s"] <= entries[1]["time_unix_s"]
    assert observer_view == entries[-1:]  # any token reads it
    assert (tmp_path / "control-audit.jsonl").is_file()
