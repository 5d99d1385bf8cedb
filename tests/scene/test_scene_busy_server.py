"""The scene reaches its viewers while the server is busy: on a loaded machine each scene
update takes long and the next one starts soon after, and the scene's changes must still go
out as they are made (a pilot's 3D view froze for 17 s on such a machine, the vehicle armed
meanwhile)."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import time
from typing import Any

import pytest
import viser
from fastapi import FastAPI
from websockets.asyncio.client import connect
from websockets.typing import Subprotocol

from server.scene import vehicle_view as vehicle_view_module
from server.scene.hub import SceneHub
from tests.api.state_fakes import pushing, scene_fed_by
from tests.serving import uvicorn_serving

from .conftest import FakeVehicle

TOKEN = "busy-scene-token"
SUBPROTOCOL = Subprotocol(f"viser-v{viser.__version__}")
# One vehicle's update as long as on a machine three times slower, under load; updates
# come back to back (the vehicle changes at 50 Hz, the scene takes 30 a second).
UPDATE_S = 0.025
SETTLE_S = 1.0  # the scene's watch goes from its idle rate to the full one
WATCHED_S = 3.0
# Each update changes the vehicle's position: held back behind the next update, a change
# reaches the viewer late or merged with later ones (measured: one message for every four
# updates, and on a loaded machine none for 17 s; without: nine for ten).
MESSAGES_PER_UPDATE = 0.45
LONGEST_SILENCE_S = 1.0


async def test_a_busy_scene_sends_its_changes_as_they_are_made(
        monkeypatch: pytest.MonkeyPatch) -> None:
    update = vehicle_view_module.VehicleView.update

    def slow_update(self: Any, *args: Any, **kwargs: Any) -> None:
        update(self, *args, **kwargs)
        time.sleep(UPDATE_S)  # the loop is held; viser's own thread may run meanwhile

    monkeypatch.setattr(vehicle_view_module.VehicleView, "update", slow_update)
    hub = SceneHub(max_rate_hz=30.0)
    app = FastAPI()
    hub.mount(app, check_token=lambda token: token == TOKEN)
    async with scene_fed_by(hub, [pushing(FakeVehicle(1))]), uvicorn_serving(app) as host, \
            connect(f"ws://{host}/scene", subprotocols=[SUBPROTOCOL],
                    additional_headers={"Cookie": f"skyhelm_token={TOKEN}"},
                    max_size=None) as ws:
        await asyncio.wait_for(ws.recv(), 10.0)
        settled = time.monotonic() + SETTLE_S
        while time.monotonic() < settled:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(ws.recv(), settled - time.monotonic())
        applied = hub.updates_applied
        heard = [time.monotonic()]
        until = heard[0] + WATCHED_S
        while (now := time.monotonic()) < until:
            try:
                await asyncio.wait_for(ws.recv(), until - now)
            except TimeoutError:
                break
            heard.append(time.monotonic())
        heard.append(time.monotonic())
        updates = hub.updates_applied - applied
    silences = [b - a for a, b in itertools.pairwise(heard)]
    messages = len(heard) - 2
    assert updates >= WATCHED_S * 10, f"the scene applied only {updates} updates"
    said = f"{messages} messages for {updates} updates; longest silence {max(silences):.2f} s"
    assert messages >= MESSAGES_PER_UPDATE * updates, said
    assert max(silences) <= LONGEST_SILENCE_S, said
