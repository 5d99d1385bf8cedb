"""The telemetry socket: anyone with a token watches one vehicle (or all) and the page-wide
topics. State is latest-wins at the asked rate (slots.py); events are queued.

A socket follows the vehicles as they come: one opened before its vehicle exists (all
vehicles, or one system id not seen yet) starts sending that vehicle's states and events as
soon as a link discovers it. A vehicle that restarts keeps its object (the link notices the
reboot), so its socket goes on."""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator

from fastapi import APIRouter, WebSocket

from server.control.publisher import StatePublisher
from server.control.publishers import StatePublishers
from server.control.registry import VehicleRegistry
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
from server.link import Link, Vehicle
from server.link.codec.aio import loop_time_s
from skyhelm_wire.calls import API_PREFIX
from skyhelm_wire.sockets import SOCKET

MIN_RATE_HZ = 0.1
# With on_change, a state at least this often whatever changed: a client that adds the time
# since the last state to its ages (the page's link box turns late past 1 s) stays true.
ON_CHANGE_KEEPALIVE_S = 0.5
# MAVLink system ids a vehicle can have; another id can never appear.
SYSID_RANGE = range(1, 256)

router = APIRouter(prefix=API_PREFIX)


def publishers_of(websocket: WebSocket) -> StatePublishers:
    publishers: StatePublishers = websocket.app.state.publishers
    return publishers


@router.websocket(SOCKET["telemetry"].route)
async def telemetry(
    websocket: WebSocket, vehicle: int | None = None, rate_hz: float = 10.0,
    on_change: bool = False,
) -> None:
    """`{type: "state"}` snapshots of one vehicle (or all) at rate_hz (capped), plus
    `{type: "statustext"}` and `{type: "event"}` as they happen; for the page also
    `{type: "vehicles"}` (the vehicle list: at once, then on every change) and
    `{type: "scene_click"}` (where a click in the 3D scene met the ground). With
    `on_change`, a tick's state is sent only when it tells something the last one sent did
    not (Published.steady) or ON_CHANGE_KEEPALIVE_S have passed since (by the server's
    clock or the state's own updated_s)."""
    context = await admit(websocket, SOCKET["telemetry"])
    if context is None:
        return
    if vehicle is not None and vehicle not in SYSID_RANGE:
        await close_socket(websocket, CLOSE_NOT_FOUND, f"no vehicle {vehicle}")
        return
    if not rate_hz > 0:  # also refuses NaN
        rate_hz = MIN_RATE_HZ
    rate_hz = min(max(rate_hz, MIN_RATE_HZ), context.settings.telemetry_max_rate_hz)
    publishers = publishers_of(websocket)
    sender = Sender(websocket)
    jobs = [
        _pump_topic(publishers.vehicle_list, sender, publishers.vehicle_list_message()),
        _pump_topic(publishers.scene_clicks, sender, None),
    ]
    jobs.append(_follow_vehicles(context.registry, vehicle, publishers, sender, rate_hz,
                                 on_change))
    await run_until_disconnect(websocket, *jobs)


async def _follow_vehicles(
    registry: VehicleRegistry, wanted: int | None, publishers: StatePublishers, sender: Sender,
    rate_hz: float, on_change: bool = False,
) -> None:
    """Pump the states and events of every vehicle (or the one wanted) known now or found
    later; ends with the first pump that fails (the client went away or was too slow)."""
    pumps: dict[int, tuple[Vehicle, list[asyncio.Task[None]]]] = {}
    follower = asyncio.current_task()

    def end_on_failure(task: asyncio.Task[None]) -> None:
        if not task.cancelled() and task.exception() is not None and follower is not None:
            follower.cancel()

    try:
        async for found in _vehicles_as_they_come(registry):
            if wanted is not None and found.sysid != wanted:
                continue
            vehicle = registry.get(found.sysid)  # the first link that saw an id owns it
            if vehicle is None or (
                    found.sysid in pumps and pumps[found.sysid][0] is vehicle):
                continue
            for task in pumps.pop(vehicle.sysid, (vehicle, []))[1]:
                task.cancel()
            running = [
                asyncio.create_task(_pump_states(publishers.for_vehicle(vehicle), sender, rate_hz,
                                                 on_change)),
                asyncio.create_task(_pump_events(vehicle, sender)),
            ]
            for task in running:
                task.add_done_callback(end_on_failure)
            pumps[vehicle.sysid] = (vehicle, running)
    finally:
        tasks = [task for _, running in pumps.values() for task in running]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


async def _vehicles_as_they_come(registry: VehicleRegistry) -> AsyncIterator[Vehicle]:
    """Every vehicle of every link, the known ones first, then each as it is discovered."""
    found: asyncio.Queue[Vehicle] = asyncio.Queue()

    async def forward(link: Link) -> None:
        queue = link.subscribe_vehicles()
        try:
            while True:
                found.put_nowait(await queue.get())
        finally:
            link.unsubscribe_vehicles(queue)

    forwarders = [asyncio.create_task(forward(link)) for link in registry.links]
    try:
        while True:
            yield await found.get()
    finally:
        for task in forwarders:
            task.cancel()
        await asyncio.gather(*forwarders, return_exceptions=True)


async def _pump_states(publisher: StatePublisher, sender: Sender, rate_hz: float,
                       on_change: bool = False) -> None:
    # Every socket of this vehicle sends the same text, encoded once per tick.
    slot = publisher.subscribe(rate_hz)
    sent: tuple[str | None, bytes] | None = None
    sent_s = -math.inf
    sent_updated_s = -math.inf
    try:
        async for published in slot:
            if on_change:
                # the keepalive by the server's clock (a stalled link still says it is) and
                # by the state's own (a link that caught up after a stall is shown as soon)
                now_s, updated_s = loop_time_s(), published.state.updated_s
                if (published.steady == sent and now_s - sent_s < ON_CHANGE_KEEPALIVE_S
                        and updated_s - sent_updated_s < ON_CHANGE_KEEPALIVE_S):
                    continue
                sent, sent_s, sent_updated_s = published.steady, now_s, updated_s
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

