"""The edge: a server started with ``--zenoh`` publishes its vehicles to the fleet and runs
REST calls that come over Zenoh (docs/fleet.md, "Edge").

What stays local: the MAVLink link, the setpoint stream, the lease, the deadman and the
envelope work exactly as without Zenoh; nothing the 2 Hz guarantee depends on goes over the
network. A fleet server that goes away changes nothing here.

Lifecycle (the app's lifespan): start() opens the session off the loop (opening blocks),
declares the api queryable, the vehicles' publications and, last, the edge's liveliness
token (so an edge seen alive already answers calls); a vehicle discovered later is published
when it appears. stop() undoes it in reverse order and closes the session.
"""

from __future__ import annotations

import asyncio
import logging
import re
import socket
import time
from collections.abc import Callable

import zenoh

from server.control.publishers import StatePublishers
from server.fleet.edge_api import EdgeApi
from server.fleet.edge_calls import EdgeCalls
from server.fleet.edge_publish import VehiclePublication
from server.fleet.keys import FleetKeys, check_name
from server.fleet.session import ZenohOptions, open_session, options_from_settings, undeclare
from server.http.context import ApiContext
from server.link import Vehicle
from server.link.codec.aio import cancel_and_wait
from server.settings import Settings

log = logging.getLogger(__name__)

# how often the vehicle list and each vehicle's connection are looked at: a vehicle's token
# follows its link within this (the link itself needs seconds to call a vehicle lost)
WATCH_PERIOD_S = 0.25
EDGE_NAME_MAX = 64


def default_edge_name(hostname: str | None = None) -> str:
    """The host name as a key chunk: [A-Za-z0-9_-] only, at most 64 characters."""
    name = re.sub(r"[^A-Za-z0-9_-]", "_", hostname or socket.gethostname())[:EDGE_NAME_MAX]
    return name or "edge"


class EdgeService:
    """One edge: its session, its token, its api queryable, one publication per vehicle."""

    def __init__(
        self,
        fleet: str,
        name: str,
        options: ZenohOptions,
        vehicles: Callable[[], list[Vehicle]],
        publishers: StatePublishers,
    ) -> None:
        self.keys = FleetKeys(fleet)
        self.name = check_name(name, "edge name")
        self.options = options
        self._vehicles = vehicles
        self._publishers = publishers
        self.session: zenoh.Session | None = None
        self.api: EdgeApi | None = None
        self.publications: dict[int, VehiclePublication] = {}
        # samples' seq start at the start time in ms: they keep growing across restarts
        self._seq_start = time.time_ns() // 1_000_000
        self._token: zenoh.LivelinessToken | None = None
        self._queryable: zenoh.Queryable[None] | None = None
        self._watch: asyncio.Task[None] | None = None

    @classmethod
    def from_settings(
        cls,
        settings: Settings,
        vehicles: Callable[[], list[Vehicle]],
        publishers: StatePublishers,
    ) -> EdgeService:
        return cls(
            settings.fleet_name,
            settings.edge_name or default_edge_name(),
            options_from_settings(settings),
            vehicles,
            publishers,
        )

    async def start(self, context: ApiContext) -> None:
        """Join the fleet (a zenoh.ZError when Zenoh cannot start) and publish; calls over
        Zenoh run on ``context``'s control core."""
        self.session = session = await asyncio.to_thread(open_session, self.options)
        try:
            calls = EdgeCalls(context, self._publishers)
            self.api = EdgeApi(calls, self.keys.api(self.name))
            self.api.bind()
            # on Zenoh's Python callback thread (indirect): measured under load, calling back
            # on Zenoh's network thread itself was slower (the GIL taken from the network
            # thread that also carries the states)
            self._queryable = session.declare_queryable(
                self.keys.api(self.name),
                zenoh.handlers.Callback(self.api.on_query),
                complete=True,
            )
            await self.refresh()
            self._watch = asyncio.create_task(self._watch_vehicles(), name="edge-watch")
            self._token = session.liveliness().declare_token(self.keys.edge_alive(self.name))
        except BaseException:
            await self.stop()
            raise
        log.info(
            "edge %s in fleet %s: publishing %d vehicle(s) under %s/%s",
            self.name, self.keys.fleet, len(self.publications), self.keys.prefix, self.name,
        )

    async def stop(self) -> None:
        await cancel_and_wait(self._watch)
        self._watch = None
        undeclare(self._queryable)
        self._queryable = None
        api, self.api = self.api, None
        if api is not None:
            await api.close()
        for publication in self.publications.values():
            await publication.close()
        self.publications.clear()
        undeclare(self._token)
        self._token = None
        session, self.session = self.session, None
        if session is not None:
            await asyncio.to_thread(session.close)

    async def refresh(self) -> None:
        """Publish vehicles that appeared; tokens follow each vehicle's connection."""
        session = self.session
        if session is None:
            return
        for vehicle in self._vehicles():
            publication = self.publications.get(vehicle.sysid)
            if publication is None or publication.vehicle is not vehicle:
                seq_start = self._seq_start
                if publication is not None:  # the link made a new Vehicle for this sysid
                    del self.publications[vehicle.sysid]
                    await publication.close()
                    seq_start = publication.last_seq  # its samples go on numbering upwards
                publication = VehiclePublication(
                    session, self.keys, self.name, vehicle,
                    self._publishers.for_vehicle(vehicle), seq_start,
                )
                self.publications[vehicle.sysid] = publication
                publication.start()
            else:
                publication.sync_alive()

    async def _watch_vehicles(self) -> None:
        while True:
            await asyncio.sleep(WATCH_PERIOD_S)
            try:
                await self.refresh()
            except zenoh.ZError as exc:  # a declaration refused: try again next time
                log.warning("edge %s: %s", self.name, exc)
