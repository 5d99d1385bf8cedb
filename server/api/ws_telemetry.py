"""The telemetry socket: anyone with a token watches one vehicle (or all) and the page-wide
topics. State is latest-wins at the asked rate (slots.py); events are queued."""

from __future__ import annotations

from fastapi import APIRouter, WebSocket

from server.control.auth import Role
from server.control.publisher import StatePublisher
from server.control.publishers import StatePublishers
from server.control.slots import Broadcast
from server.control.views import event_message
from server.http.ws_common import (
    CLOSE_NOT_FOUND,
    EVENT_BACKLOG,
    Sender,
    admit,
    close_socket,
    run_until_disconnect,
)
from server.link import Vehicle

MIN_RATE_HZ = 0.1

router = APIRouter()


def publishers_of(websocket: WebSocket) -> StatePublishers:
    publishers: StatePublishers = websocket.app.state.publishers
    return publishers


@router.websocket("/ws/telemetry")
async def telemetry(
    websocket: WebSocket, vehicle: int | None = None, rate_hz: float = 10.0
) -> None:
    """`{type: "state"}` snapshots of one vehicle (or all) at rate_hz (capped), plus
    `{type: "statustext"}` and `{type: "event"}` as they happen; for the page also
    `{type: "vehicles"}` (the vehicle list: at once, then on every change) and
    `{type: "scene_click"}` (where a click in the 3D scene met the ground)."""
    context = await admit(websocket, Role.OBSERVER)
    if context is None:
        return
    if vehicle is None:
        vehicles = context.registry.all()
    else:
        found = context.registry.get(vehicle)
        if found is None:
            await close_socket(websocket, CLOSE_NOT_FOUND, f"no vehicle {vehicle}")
            return
        vehicles = [found]
    if not rate_hz > 0:  # also refuses NaN
        rate_hz = MIN_RATE_HZ
    rate_hz = min(max(rate_hz, MIN_RATE_HZ), context.settings.telemetry_max_rate_hz)
    publishers = publishers_of(websocket)
    sender = Sender(websocket)
    jobs = [
        _pump_topic(publishers.vehicle_list, sender, publishers.vehicle_list_message()),
        _pump_topic(publishers.scene_clicks, sender, None),
    ]
    for each in vehicles:
        jobs.append(_pump_states(publishers.for_vehicle(each), sender, rate_hz))
        jobs.append(_pump_events(each, sender))
    await run_until_disconnect(websocket, *jobs)


async def _pump_states(publisher: StatePublisher, sender: Sender, rate_hz: float) -> None:
    # Every socket of this vehicle sends the same text, encoded once per tick.
    slot = publisher.subscribe(rate_hz)
    try:
        async for published in slot:
            await sender.send_text(published.message)
    finally:
        publisher.unsubscribe(slot)


async def _pump_topic(topic: Broadcast, sender: Sender, current: str | None) -> None:
    slot = topic.subscribe(current)
    try:
        async for text in slot:
            await sender.send_text(text)
    finally:
        topic.unsubscribe(slot)


async def _pump_events(vehicle: Vehicle, sender: Sender) -> None:
    queue = vehicle.subscribe_events(EVENT_BACKLOG)
    try:
        while True:
            await sender.send_json(event_message(vehicle.sysid, await queue.get()))
    finally:
        unsubscribe = getattr(vehicle, "unsubscribe_events", None)
        if unsubscribe is not None:
            unsubscribe(queue)

