"""The fleet socket, ``/api/v1/fleet/ws?rate_hz=``: every fleet vehicle's state latest-wins
at the client's rate (`fleet_state`), presence as it changes (`presence`, first a snapshot
of who is alive), and the vehicles' events and messages (`event`). Same admission as the
telemetry socket (ws_common.py): any token reads."""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, WebSocket

from server.fleet.view import FleetView, Watcher
from server.fleet.view_service import FleetService
from server.http.ws_common import Sender, admit, run_until_disconnect
from skyhelm_wire.calls import API_PREFIX
from skyhelm_wire.sockets import SOCKET

MIN_RATE_HZ = 0.1

router = APIRouter(prefix=API_PREFIX)


@router.websocket(SOCKET["fleet"].route)
async def fleet_socket(websocket: WebSocket, rate_hz: float = 10.0) -> None:
    context = await admit(websocket, SOCKET["fleet"])
    if context is None:
        return
    if not rate_hz > 0:  # also refuses NaN
        rate_hz = MIN_RATE_HZ
    rate_hz = min(max(rate_hz, MIN_RATE_HZ), context.settings.telemetry_max_rate_hz)
    service: FleetService = websocket.app.state.fleet
    view = service.view
    watcher = view.watch()  # before the snapshot: a change meanwhile is sent twice, not lost
    sender = Sender(websocket)
    try:
        for message in view.presence_messages():
            await sender.send_json(message)
        await run_until_disconnect(
            websocket,
            _pump_states(view, watcher, sender, 1.0 / rate_hz),
            _pump_queued(watcher, sender),
        )
    finally:
        view.unwatch(watcher)


async def _pump_states(view: FleetView, watcher: Watcher, sender: Sender, period_s: float) -> None:
    """Each vehicle's newest state at most once per period; nothing when nothing changed."""
    sent: dict[str, int] = {}
    while True:
        await watcher.states_changed.wait()
        watcher.states_changed.clear()
        for vehicle in view.vehicles():
            if vehicle.state is None or sent.get(vehicle.key) == vehicle.version:
                continue
            sent[vehicle.key] = vehicle.version
            await sender.send_text(vehicle.state_message())
        await asyncio.sleep(period_s)


async def _pump_queued(watcher: Watcher, sender: Sender) -> None:
    while True:
        await sender.send_json(await watcher.queue.get())
