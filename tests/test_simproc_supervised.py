"""The embedded simulated vehicle's process killed (-9) under a running server: its end is
seen at once, logged once with the cause, raised as a ``process`` event and shown by
``/api/v1/health``; its vehicle is lost at once with that cause (not a second later, for its
silence), and a control call is refused saying so."""

from __future__ import annotations

import asyncio
import logging
import os
import signal
import time

import httpx
import pytest

from server.link import VehicleEvent
from tests.api.conftest import app_running, auth, make_settings
from tests.link.conftest import drain
from tests.waiting import eventually


async def test_a_killed_simulated_vehicle_is_seen_at_once_and_said_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.ERROR, logger="server.simproc")
    async with app_running(make_settings(None, sim_speed=4.0)) as app:
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://testserver",
                                     headers=auth()) as client:
            sim = app.state.sim
            assert sim is not None
            vehicle = app.state.api.registry.all()[0]
            events: asyncio.Queue[VehicleEvent] = vehicle.subscribe_events()
            before = (await client.get("/api/v1/health")).json()
            mine = next(p for p in before["processes"] if p["name"] == "simulated vehicle")
            assert mine["running"] is True
            assert mine["pid"] == sim.pid
            killed = time.monotonic()
            os.kill(sim.pid, signal.SIGKILL)

            told: list[VehicleEvent] = []

            async def fault_event() -> VehicleEvent:
                while True:
                    told.append(event := await events.get())
                    if event.kind == "process":
                        return event

            event = await asyncio.wait_for(fault_event(), 5.0)
            noticed_s = time.monotonic() - killed
            # lost with it, before the link's silence bound (1 s) could tell
            assert vehicle.connected is False
            lost = [e for e in told + drain(events) if e.kind == "connection"]
            assert [e.data["reason"] for e in lost] == [
                "simulated vehicle's process ended (killed by SIGKILL)"]
            lease = (await client.post("/api/v1/vehicles/1/control", json={})).json()
            refused = await client.post("/api/v1/vehicles/1/arm", json={},
                                        headers={"X-Lease-Id": lease["lease_id"]})
            assert refused.status_code == 503
            assert refused.json()["detail"]["reason"] == (
                "vehicle 1 is not connected: simulated vehicle's process ended "
                "(killed by SIGKILL)")
            state = (await client.get("/api/v1/vehicles/1")).json()
            assert state["connected"] is False
            assert state["lost_reason"] == "simulated vehicle's process ended (killed by SIGKILL)"

            async def health_says() -> dict[str, object] | None:
                body = (await client.get("/api/v1/health")).json()
                found = next(p for p in body["processes"] if p["name"] == "simulated vehicle")
                return found if found["running"] is False else None

            after = await eventually(health_says, 5.0, "the health says it ended")
            await asyncio.sleep(0.5)  # a second report would come by now
    print(f"simulated vehicle kill -9 noticed in {noticed_s * 1000:.0f} ms")
    assert noticed_s < 0.5  # at once: the exit is awaited, not polled for
    assert event.data["process"] == "simulated vehicle"
    assert "SIGKILL" in str(event.data["fault"])
    assert after is not None
    assert after["last_fault"] == "killed by SIGKILL"
    assert after["faults"] == 1
    said = [r for r in caplog.records if "simulated vehicle's process" in r.getMessage()]
    assert len(said) == 1
    assert "killed by SIGKILL" in said[0].getMessage()
