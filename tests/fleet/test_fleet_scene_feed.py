"""A fleet server with its 3D scene: the fleet view feeds the scene every fleet vehicle it
hears of (app.py wires FleetView.on_change to SceneHub.fleet), over real Zenoh on loopback
from a stand-in edge."""

from __future__ import annotations

import asyncio
from typing import Any

import httpx

from server.fleet.keys import FleetKeys
from tests.api.conftest import PILOT, app_running, make_settings
from tests.fleet.fake_edge import FakeEdge, free_tcp_endpoint, loopback_options
from tests.waiting import eventually

FLEET = "scenefleet"
STATE: dict[str, Any] = {
    "id": 1, "type": "QUADROTOR", "mode": "HOLD", "armed": False, "connected": True,
    "global": {"lat_deg": 47.397742, "lon_deg": 8.545594, "alt_amsl_m": 488.0,
               "alt_rel_m": 0.0},
    "attitude": {"roll_deg": 0.0, "pitch_deg": 0.0, "yaw_deg": 0.0},
}


async def test_fleet_vehicles_reach_the_scene() -> None:
    endpoint = free_tcp_endpoint()
    settings = make_settings(None, fleet=True, fleet_name=FLEET, zenoh_listen=[endpoint],
                             zenoh_multicast_scouting=False, scene=True)
    async with app_running(settings) as app, httpx.AsyncClient(
        transport=httpx.ASGITransport(app=app), base_url="http://testserver", timeout=30.0,
    ) as client:
        edge = await asyncio.to_thread(
            FakeEdge.open, FleetKeys(FLEET), "edge-s", loopback_options(connect=[endpoint])
        )
        try:
            edge.vehicle_up(1)

            async def drawn() -> list[str]:
                edge.publish_state(1, STATE)
                status = (await client.get("/scene/api/status", params={"token": PILOT})).json()
                keys: list[str] = status["fleet_vehicles"]
                return keys

            assert await eventually(drawn, 20.0, "the fleet vehicle in the scene") == [
                "edge-s/1"
            ]
        finally:
            await asyncio.to_thread(edge.close)
        # the fleet server's own vehicles: none (no --connect, no --sim-count)
        status = (await client.get("/scene/api/status", params={"token": PILOT})).json()
        assert status["vehicles"] == []
