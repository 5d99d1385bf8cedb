"""The fleet server's part of a server started with ``--fleet``: its own Zenoh session, the
view it feeds, and the edge calls made on that session. Opened and closed by the app's
lifespan; opening Zenoh blocks, so it runs off the loop."""

from __future__ import annotations

import asyncio
import logging

import zenoh

from server.fleet.keys import FleetKeys, StateTier
from server.fleet.proxy import QUERY_TIMEOUT_S
from server.fleet.session import ZenohOptions, open_session, options_from_settings
from server.fleet.view import FleetView
from server.fleet.view_zenoh import FleetFeed
from server.settings import Settings

log = logging.getLogger(__name__)


class FleetService:
    """The view is there from the start (empty); the session once started."""

    def __init__(
        self,
        fleet: str,
        options: ZenohOptions,
        tier: StateTier = "fast",
        takeover_ask_s: float = 10.0,
    ) -> None:
        self.keys = FleetKeys(fleet)
        self.options = options
        self.tier: StateTier = tier
        self.view = FleetView(fleet)
        self.session: zenoh.Session | None = None
        self.feed: FleetFeed | None = None
        # how long an edge has to answer a proxied call (504 after)
        self.query_timeout_s = QUERY_TIMEOUT_S
        # how long an edge holds an ask for control for the holder's answer: the fleet and
        # its edges share this setting, as they share tokens (added to that call's timeout)
        self.takeover_ask_s = takeover_ask_s

    @classmethod
    def from_settings(cls, settings: Settings) -> FleetService:
        return cls(
            settings.fleet_name, options_from_settings(settings),
            takeover_ask_s=settings.takeover_ask_s,
        )

    async def start(self) -> None:
        """Open the session (a ZError when Zenoh cannot start) and subscribe."""
        self.session = await asyncio.to_thread(open_session, self.options)
        self.feed = FleetFeed(self.session, self.view, self.tier)
        self.feed.start()
        log.info("fleet %s: watching %s", self.keys.fleet, self.keys.prefix)

    async def stop(self) -> None:
        if self.feed is not None:
            self.feed.stop()
            self.feed = None
        session, self.session = self.session, None
        if session is not None:
            await asyncio.to_thread(session.close)
