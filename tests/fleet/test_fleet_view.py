"""The fleet server in-process against a stand-in edge (fake_edge.py) over real Zenoh on
loopback: what it lists, how fast it sees an edge go, what it forwards to an edge and what it
hands back, the fleet socket. The real edge and separate processes: test_fleet_processes.py."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import httpx
import pytest
from fastapi import FastAPI
from websockets.asyncio.client import connect

from server.fleet.keys import FleetKeys
from server.fleet.view_service import FleetService
from tests.api.conftest import OBSERVER, PILOT, app_running, auth, make_settings
from tests.api.test_ws import close_code, receive, receive_until
from tests.fleet.fake_edge import FakeEdge, free_tcp_endpoint, loopback_options
from tests.serving import uvicorn_serving
from tests.waiting import wait_for

FLEET = "testfleet"
STATE = {
    "id": 1, "type": "quadrotor", "mode": "HOLD", "armed": False, "connected": True,
    "global": {"lat_deg": 47.39, "lon_deg": 8.54, "alt_m": 488.0},
    "position_ned": {"north_m": 1.0, "east_m": 2.0, "down_m": -3.0},
    "lease": {"holder": "pilot · tab 1", "expires_in_s": 100.0},
}


@dataclass
class Rig:
    app: FastAPI
    client: httpx.AsyncClient
    edge: FakeEdge
    endpoint: str

    @property
    def fleet(self) -> FleetService:
        service: FleetService = self.app.state.fleet
        return service


@contextlib.asynccontextmanager
async def rig() -> AsyncIterator[Rig]:
    """A fleet server (no vehicle of its own, so no sim) listening on loopback, and a
    stand-in edge connected to it with one vehicle."""
    endpoint = free_tcp_endpoint()
    settings = make_settings(
        None, fleet=True, fleet_name=FLEET, zenoh_listen=[endpoint],
        zenoh_multicast_scouting=False,
    )
    async with app_running(settings) as app:
        edge = await asyncio.to_thread(
            FakeEdge.open, FleetKeys(FLEET), "edge-a", loopback_options(connect=[endpoint])
        )
        edge.vehicle_up(1)
        async with httpx.AsyncClient(
            transport=httpx.ASGITransport(app=app), base_url="http://testserver",
            headers=auth(), timeout=30.0,
        ) as client:
            r = Rig(app, client, edge, endpoint)
            try:
                yield r
            finally:
                await asyncio.to_thread(r.edge.close)  # the one running now (restarts)


@pytest.fixture
async def fleet_rig() -> AsyncIterator[Rig]:
    async with rig() as r:
        yield r


def has_state(r: Rig, edge: str, vehicle_id: int) -> bool:
    found = r.fleet.view.vehicle(edge, vehicle_id)
    return found is not None and found.state is not None


def edge_alive(r: Rig, edge: str) -> bool:
    found = r.fleet.view.edge(edge)
    return found is not None and found.alive


def vehicle_alive(r: Rig, edge: str, vehicle_id: int) -> bool:
    found = r.fleet.view.vehicle(edge, vehicle_id)
    return found is not None and found.alive


async def test_lists_edges_and_vehicles_with_freshness_and_controller(fleet_rig: Rig) -> None:
    r = fleet_rig
    assert r.app.state.sim is None  # a fleet server with no --sim-count starts no vehicle
    assert (await r.client.get("/api/v1/vehicles")).json() == []
    assert (await r.client.get("/api/v1/config")).json()["fleet"] is True
    await wait_for(lambda: vehicle_alive(r, "edge-a", 1), 10.0, "the vehicle's token")
    r.edge.publish_state(1, STATE)
    await wait_for(lambda: has_state(r, "edge-a", 1), 10.0, "the state")
    fleet = (await r.client.get("/api/v1/fleet", headers=auth(OBSERVER))).json()
    assert fleet == {"fleet": FLEET, "edges": [{"edge": "edge-a", "alive": True, "vehicles": [1]}]}
    [row] = (await r.client.get("/api/v1/fleet/vehicles", headers=auth(OBSERVER))).json()
    assert row["key"] == "edge-a/1"
    assert row["edge"] == "edge-a"
    assert row["id"] == 1
    assert row["alive"] is True
    assert row["controller"] == "pilot · tab 1"
    assert (row["type"], row["mode"], row["armed"], row["connected"]) == (
        "quadrotor", "HOLD", False, True,
    )
    assert row["global"] == STATE["global"]
    assert row["position_ned"] == STATE["position_ned"]
    assert 0.0 <= row["age_s"] < 30.0
    assert -5.0 < row["state_age_s"] < 30.0
    detail = await r.client.get("/api/v1/fleet/edges/edge-a/vehicles/1")
    assert detail.status_code == 200
    assert detail.json()["mode"] == "HOLD"
    assert detail.json()["alive"] is True
    assert detail.json()["lease"] == STATE["lease"]
    missing = await r.client.get("/api/v1/fleet/edges/edge-a/vehicles/9")
    assert missing.status_code == 404
    assert (await r.client.get("/api/v1/fleet")).status_code == 200
    no_token = await r.client.get("/api/v1/fleet/vehicles", headers={"Authorization": ""})
    assert no_token.status_code == 401

    # malformed samples are counted and dropped; the view goes on
    assert r.fleet.feed is not None
    r.edge.session.put(f"skyhelm/{FLEET}/edge-a/1/state/fast", b"\xff not json")
    r.edge.session.put(f"skyhelm/{FLEET}/edge-a/1/state/fast", b"[1, 2]")
    await wait_for(lambda: r.fleet.feed is not None and r.fleet.feed.dropped == 2, 10.0, "drops")

    # a vehicle's token goes: lost at once, still listed with its last state
    r.edge.vehicle_down(1)
    await wait_for(lambda: not vehicle_alive(r, "edge-a", 1), 5.0, "the vehicle lost")
    [row] = (await r.client.get("/api/v1/fleet/vehicles")).json()
    assert row["alive"] is False
    assert row["mode"] == "HOLD"
    r.edge.vehicle_up(1)
    await wait_for(lambda: vehicle_alive(r, "edge-a", 1), 5.0, "the vehicle back")

    # a fleet server started after the edge sees who is alive at once (liveliness history)
    late = FleetService(FLEET, loopback_options(connect=r.edge.listen))
    await late.start()
    try:
        await wait_for(
            lambda: (found := late.view.vehicle("edge-a", 1)) is not None and found.alive,
            10.0, "the late fleet server to see the vehicle",
        )
        assert late.view.summary() == fleet
    finally:
        await late.stop()


async def test_an_edge_that_goes_away_is_lost_and_comes_back(fleet_rig: Rig) -> None:
    r = fleet_rig
    await wait_for(lambda: vehicle_alive(r, "edge-a", 1), 10.0, "the vehicle's token")
    await asyncio.to_thread(r.edge.close)  # closing twice is harmless
    # the edge's token and its vehicle's go as two events, in either order; the edge lost
    # takes its vehicles with it
    lost_in_s = await wait_for(lambda: not edge_alive(r, "edge-a"), 10.0, "the edge lost")
    assert lost_in_s < 2.0
    assert r.fleet.view.edge("edge-a") is not None
    assert not vehicle_alive(r, "edge-a", 1)
    # calls to a lost edge: 503 at once, nothing sent
    refused = await r.client.post("/api/v1/fleet/edges/edge-a/vehicles/1/arm", json={})
    assert refused.status_code == 503
    assert "not alive" in refused.json()["detail"]["reason"]
    unknown = await r.client.post("/api/v1/fleet/edges/nobody/vehicles/1/arm", json={})
    assert unknown.status_code == 404

    # the edge restarts (a new session, same name): alive again by itself
    r.edge = await asyncio.to_thread(
        FakeEdge.open, FleetKeys(FLEET), "edge-a", loopback_options(connect=[r.endpoint])
    )
    r.edge.vehicle_up(1)
    await wait_for(lambda: vehicle_alive(r, "edge-a", 1), 10.0, "the vehicle back")
    assert edge_alive(r, "edge-a")


async def test_calls_go_to_the_edge_with_the_callers_authority(fleet_rig: Rig) -> None:
    r = fleet_rig
    await wait_for(lambda: edge_alive(r, "edge-a"), 10.0, "the edge")
    refused = {"detail": {"reason": "the call needs the vehicle's control lease (X-Lease-Id)"}}
    r.edge.answer = {"status": 423, "headers": {"retry-after": "3", "x-other": "no"},
                     "body": refused}
    answer = await r.client.post(
        "/api/v1/fleet/edges/edge-a/vehicles/1/takeoff?wait=1&token=leaked",
        json={"alt_m": 5.0}, headers={"X-Lease-Id": "lease-123", "X-Client-Name": "x"},
    )
    assert answer.status_code == 423
    assert answer.json() == refused
    assert answer.headers["retry-after"] == "3"
    assert "x-other" not in answer.headers
    [sent] = r.edge.queries
    assert sent == {
        "method": "POST",
        "path": "/api/v1/vehicles/1/takeoff",
        "query": "wait=1",
        "headers": {"authorization": f"Bearer {PILOT}", "x-lease-id": "lease-123"},
        "body": {"alt_m": 5.0},
    }
    # an observer reads through the edge, and is refused here before anything is sent
    r.edge.answer = {"status": 200, "headers": {}, "body": {"rate_hz": 20.0}}
    read = await r.client.get(
        "/api/v1/fleet/edges/edge-a/vehicles/1/stream", headers=auth(OBSERVER)
    )
    assert (read.status_code, read.json()) == (200, {"rate_hz": 20.0})
    assert r.edge.queries[-1]["headers"] == {"authorization": f"Bearer {OBSERVER}"}
    assert r.edge.queries[-1]["body"] is None
    flying = await r.client.post(
        "/api/v1/fleet/edges/edge-a/vehicles/1/arm", json={}, headers=auth(OBSERVER)
    )
    assert flying.status_code == 403
    assert len(r.edge.queries) == 2
    # bad input is ours to refuse
    for path, body in (("../../signing", "{}"), ("arm", "{not json"), ("arm", '{"a": NaN}')):
        bad = await r.client.post(
            f"/api/v1/fleet/edges/edge-a/vehicles/1/{path}", content=body
        )
        assert bad.status_code in (404, 422), (path, bad.text)
    assert len(r.edge.queries) == 2
    # an edge that never answers: 504 once the query times out
    r.edge.answer = "silent"
    r.fleet.query_timeout_s = 0.5
    silent = await r.client.post("/api/v1/fleet/edges/edge-a/vehicles/1/land", json={})
    assert silent.status_code == 504
    assert "did not answer" in silent.json()["detail"]["reason"]


async def test_the_fleet_socket_sends_presence_states_and_events(fleet_rig: Rig) -> None:
    r = fleet_rig
    await wait_for(lambda: vehicle_alive(r, "edge-a", 1), 10.0, "the vehicle's token")
    async with uvicorn_serving(r.app) as host:
        url = f"ws://{host}/api/v1/fleet/ws?rate_hz=20"
        async with connect(f"{url}&token={OBSERVER}") as ws:
            seen = [await receive(ws), await receive(ws)]
            assert {m["key"]: m["alive"] for m in seen if m["type"] == "presence"} == {
                "edge-a": True, "edge-a/1": True,
            }
            r.edge.publish_state(1, STATE)
            state = await receive_until(ws, {"type": "fleet_state"})
            assert (state["key"], state["edge"], state["id"], state["alive"]) == (
                "edge-a/1", "edge-a", 1, True,
            )
            assert state["state"]["mode"] == "HOLD"
            assert state["age_s"] >= 0.0
            event = {"type": "event", "vehicle": 1, "kind": "armed", "time_s": 1.0, "data": {}}
            r.edge.publish_event(1, event)
            got = await receive_until(ws, {"type": "event"})
            assert got["key"] == "edge-a/1"
            assert got["event"]["kind"] == "armed"
            r.edge.vehicle_down(1)
            lost = await receive_until(ws, {"type": "presence", "key": "edge-a/1"})
            assert lost["alive"] is False
            assert lost["id"] == 1
        async with connect(url) as ws:
            assert await close_code(ws) == 4401


async def test_a_fleet_server_may_fly_its_own_vehicles_too() -> None:
    """--fleet with --sim-count starts the sim as any server does (no vehicle needed here:
    only the decision is checked)."""
    from server.app import starts_sim

    assert not starts_sim(make_settings(None, fleet=True))
    assert starts_sim(make_settings(None, fleet=True, sim_count=2))
    assert starts_sim(make_settings(None))
    assert not starts_sim(make_settings("udpin:127.0.0.1:0", fleet=True, sim_count=2))


def test_the_view_keeps_the_newest_state_and_presence() -> None:
    from server.fleet.view import FleetView

    view = FleetView(FLEET)
    view.set_alive("e", 3, True)
    view.set_state("e", 3, {"seq": 5, "sent_unix_s": 1.0, "state": STATE})
    view.set_state("e", 3, {"seq": 1, "sent_unix_s": 2.0, "state": {**STATE, "mode": "LAND"}})
    vehicle = view.vehicle("e", 3)
    assert vehicle is not None
    assert vehicle.state is not None
    assert vehicle.state["mode"] == "LAND"  # a restarted edge's seq starts again
    assert (vehicle.seq, vehicle.sent_unix_s) == (1, 2.0)
    view.set_state("e", 3, {"seq": 2, "state": "not an object"})  # ignored
    assert vehicle.seq == 1
    message: dict[str, Any] = json.loads(vehicle.state_message())
    assert message["type"] == "fleet_state"
    assert message["key"] == "e/3"
    view.set_alive("e", None, True)
    view.set_alive("e", None, False)  # the edge's token went: its vehicles with it
    assert not vehicle.alive
