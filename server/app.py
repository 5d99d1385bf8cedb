"""The FastAPI application: API v1, the 3D scene, the static page, and a lifespan that opens
the links (starting the simulated vehicle first when no --connect is given). A ``tlog:``
link (``skyhelm replay``) makes the whole API read-only."""

from __future__ import annotations

import asyncio
import gc
import logging
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fastapi import APIRouter, FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.staticfiles import StaticFiles

from server.api import ws
from server.api.routes import (
    commands,
    control,
    health,
    intents,
    page_config,
    params,
    session,
    setpoint,
    sticks,
    tiles,
    vehicles,
)
from server.api.routes import signing as signing_routes
from server.control.auth import TokenChecker
from server.control.deadman import Deadman
from server.control.lease import LeaseManager
from server.control.publishers import StatePublishers
from server.control.registry import VehicleRegistry
from server.fleet import routes as fleet_routes
from server.fleet import ws as fleet_ws
from server.fleet.edge import EdgeService
from server.fleet.view import FleetVehicle
from server.fleet.view_service import FleetService
from server.foxglove import FoxgloveBridge, FoxgloveProxy
from server.http.context import ApiContext
from server.http.contract import hold_to_contract
from server.http.error_handlers import install_error_handlers
from server.http.security import install_security
from server.http.tile_archive import open_tile_archive
from server.link import Envelope, Link
from server.link.codec.signing_keys import SigningKeyError, SigningKeyStore
from server.link.codec.urls import parse_link_url
from server.settings import Settings
from server.simproc import SimProcess
from skyhelm_wire.messages import SceneClickMessage

if TYPE_CHECKING:
    from server.scene.fleet_view import FleetScene
    from server.scene.hub import SceneHub

log = logging.getLogger(__name__)


class StartupError(RuntimeError):
    """The server cannot start: a link would not open or a vehicle never appeared."""


def create_app(settings: Settings, *, freeze_gc_at_start: bool = False) -> FastAPI:
    """``freeze_gc_at_start`` (the served process, not tests that build many apps): what
    start-up built moves out of the collector's reach (gc.freeze), so a later full
    collection walks less and holds the GIL, and with it the stream's sender thread, for
    less time."""
    tokens = TokenChecker.from_settings(settings)
    envelope = Envelope(
        max_alt_rel_m=settings.max_alt_rel_m,
        max_distance_m=settings.max_distance_m,
        max_speed_xy_m_s=settings.max_speed_xy_m_s,
        max_speed_z_m_s=settings.max_speed_z_m_s,
    )
    registry = VehicleRegistry(envelope, settings.rate_hz)
    leases = LeaseManager.from_settings(settings)
    deadman = Deadman.from_settings(leases, registry, settings)
    context = ApiContext(
        settings, tokens, registry, leases, deadman, read_only=is_replay(settings.connect),
        tiles=open_tile_archive(settings.map_tiles) if settings.map_tiles else None,
    )
    hub = _scene_hub() if settings.scene else None
    publishers = StatePublishers(
        registry.all, leases.status, max_rate_hz=settings.telemetry_max_rate_hz
    )

    fleet = FleetService.from_settings(settings) if settings.fleet else None
    if fleet is not None and hub is not None:
        fleet.view.on_change.append(_show_in_scene(hub.fleet))
    edge = EdgeService.from_settings(settings, registry.all, publishers) if settings.zenoh else None
    foxglove = _foxglove_bridge(settings)
    attach = foxglove.attach if foxglove is not None else None

    def tell_vehicles(data: dict[str, Any]) -> None:
        """A supervised process's fault or recovery, as a ``process`` event of every vehicle."""
        for vehicle in registry.all():
            vehicle.publish_event("process", data)

    if foxglove is not None:
        foxglove.on_change.append(tell_vehicles)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        sim: SimProcess | None = None
        try:
            signing_store = app.state.signing_store = _signing_store(settings)
            if foxglove is not None:
                await foxglove.open()
            if settings.connect:
                await _open_links(registry, settings, settings.connect, signing_store, attach)
            elif starts_sim(settings):  # a fleet server may have no vehicle of its own
                sim = SimProcess(
                    airframe=settings.sim_airframe,
                    count=settings.sim_count,
                    speed=settings.sim_speed,
                    signing_dir=_sim_signing_dir(signing_store),
                )
                app.state.sim = sim
                sim.on_change.append(tell_vehicles)
                sim.on_change.append(_lose_sim_vehicles(registry))
                instances = await sim.start()
                await _open_links(
                    registry, settings, [i.url for i in instances], signing_store, attach
                )
                await _wait_for_vehicles(registry, [i.sysid for i in instances], settings)
            await deadman.start()
            await publishers.start(registry.links)
            if foxglove is not None:
                await foxglove.start(publishers)
            if fleet is not None:
                await _start_fleet(fleet)
            if edge is not None:
                await _start_edge(edge, context)
            if hub is not None:
                hub.on_click = _on_loop(publishers.publish_click)
                await hub.start(publishers)
            if freeze_gc_at_start:
                gc.collect()
                gc.freeze()
            yield
        finally:
            if edge is not None:
                await edge.stop()
            if fleet is not None:
                await fleet.stop()
            if hub is not None:
                await hub.stop()
            await publishers.close()
            await deadman.stop()
            for link in registry.remove_links():
                await link.close()
            if foxglove is not None:
                await foxglove.close()
            if sim is not None:
                await sim.stop()
            if context.tiles is not None:
                context.tiles.close()

    app = FastAPI(
        title="SkyHelm",
        summary="Ground control for PX4 vehicles: REST + WebSocket over one MAVLink link",
        version="1",
        lifespan=lifespan,
    )
    app.state.api = context
    app.state.sim = None
    app.state.publishers = publishers
    app.state.signing_store = None  # the lifespan reads the key file
    app.state.fleet = fleet
    app.state.edge = edge
    app.state.foxglove = foxglove
    install_error_handlers(app)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["*"],
            allow_headers=["Authorization", "Content-Type", "X-Lease-Id"],
        )
    # Every route under API_PREFIX is made once, when its module is imported (its router
    # carries the prefix), and every app holds those same route objects: FastAPI's
    # include_router builds each route of the included router again for each app it is
    # included in (its parameters' and answers' models: ~1 CPU-s per app, of an app the
    # tests make by the hundred and `skyhelm serve` makes at each start).
    routers: list[APIRouter] = []
    if fleet is not None:
        # first: routes are tried in order (each costs ~5 us), and a call proxied to an edge
        # is the one whose latency counts twice
        routers += [fleet_routes.router, fleet_ws.router]
    routers += [
        module.router
        for module in (
            health,
            session,
            page_config,
            tiles,
            vehicles,
            control,
            commands,
            intents,
            setpoint,
            sticks,
            params,
            signing_routes,
        )
    ]
    routers += ws.ROUTERS
    app.router.routes.extend(route for router in routers for route in router.routes)
    hold_to_contract(app, settings)
    if hub is not None:
        hub.mount(app, check_token=tokens.is_valid)
    if foxglove is not None and settings.foxglove_port is not None:
        FoxgloveProxy(lambda: foxglove.port, tokens.is_valid).mount(app)
    if settings.web_dir is not None:
        app.mount("/", StaticFiles(directory=settings.web_dir, html=True), name="web")
    install_security(app, tokens, context.guards, settings.cors_origins)
    return app


def _on_loop(
    publish: Callable[[dict[str, object]], None],
) -> Callable[[SceneClickMessage], None]:
    """Clicks come from viser's thread; the page learns of them on its telemetry socket."""
    loop = asyncio.get_running_loop()

    def on_click(click: SceneClickMessage) -> None:
        loop.call_soon_threadsafe(publish, click.model_dump(exclude={"type"}))

    return on_click


def _scene_hub() -> SceneHub:
    """The 3D scene: viser (half a second of imports) is loaded only for a server that
    shows it, not for ``--no-scene`` nor the other commands."""
    from server.scene.hub import SceneHub

    return SceneHub()


def _show_in_scene(scene: FleetScene) -> Callable[[FleetVehicle], None]:
    """The fleet view tells the 3D scene of every fleet vehicle's state and presence."""

    def show(vehicle: FleetVehicle) -> None:
        if vehicle.state is not None:
            scene.show(vehicle.key, vehicle.state, vehicle.alive)

    return show


def _foxglove_bridge(settings: Settings) -> FoxgloveBridge | None:
    """Foxglove's server with --foxglove-port, MCAP files with --mcap (beside the .tlogs)."""
    if settings.foxglove_port is None and not (settings.mcap and settings.log_dir is not None):
        return None
    return FoxgloveBridge(
        port=settings.foxglove_port, record_mcap=settings.mcap,
        state_rate_hz=settings.telemetry_max_rate_hz,
    )


def starts_sim(settings: Settings) -> bool:
    """No --connect starts the simulated vehicle(s); but a fleet server (--fleet) starts
    none unless --sim-count (or SKYHELM_SIM_COUNT) asks for some."""
    if settings.connect:
        return False
    return not settings.fleet or "sim_count" in settings.model_fields_set


async def _start_fleet(fleet: FleetService) -> None:
    try:
        await fleet.start()
    except Exception as exc:  # zenoh.ZError: a bad endpoint, config or port in use
        raise StartupError(f"cannot join the fleet over Zenoh: {exc}") from exc


async def _start_edge(edge: EdgeService, context: ApiContext) -> None:
    try:
        await edge.start(context)
    except Exception as exc:  # zenoh.ZError: a bad endpoint, config or port in use
        raise StartupError(f"cannot publish to the fleet over Zenoh: {exc}") from exc


def is_replay(urls: list[str]) -> bool:
    """A server that replays a recording is read-only: there is no vehicle to command."""
    return any(parse_link_url(url).kind == "tlog" for url in urls)


def _signing_store(settings: Settings) -> SigningKeyStore | None:
    if settings.signing_key_file is None:
        return None
    try:
        return SigningKeyStore(settings.signing_key_file)
    except SigningKeyError as exc:
        raise StartupError(str(exc)) from None


def _sim_signing_dir(store: SigningKeyStore | None) -> Path | None:
    """The embedded sim's key files live beside the server's, so both survive restarts."""
    return store.key_file.parent / "sim" if store is not None else None


async def _open_links(
    registry: VehicleRegistry, settings: Settings, urls: list[str],
    signing_store: SigningKeyStore | None = None,
    on_open: Callable[[Link], None] | None = None,
) -> None:
    for url in urls:
        # Recording a replay would only copy the file being replayed.
        log_dir = None if is_replay([url]) else settings.log_dir
        try:
            link = await Link.open(
                url, log_dir=log_dir, heartbeat_timeout_s=settings.heartbeat_timeout_s,
                silence_timeout_s=settings.silence_timeout_s,
                # a recording is shown as it was recorded: nothing to sign or check
                signing_store=None if is_replay([url]) else signing_store,
                on_open=on_open,
            )
        except OSError as exc:
            raise StartupError(f"cannot open {url}: {exc}") from exc
        registry.add_link(link)


def _lose_sim_vehicles(registry: VehicleRegistry) -> Callable[[dict[str, Any]], None]:
    """The embedded simulated vehicle's process ended: its vehicles are lost at once, with
    that cause, rather than a second later for their silence."""

    def lose(data: dict[str, Any]) -> None:
        if not data.get("running", True):
            for link in registry.links:
                link.peer_gone(str(data["text"]))

    return lose


async def _wait_for_vehicles(
    registry: VehicleRegistry, sysids: list[int], settings: Settings
) -> None:
    """The URL is printed only once every simulated vehicle is talking."""
    deadline = time.monotonic() + settings.vehicle_wait_s
    while True:
        missing = [sysid for sysid in sysids if registry.get(sysid) is None]
        if not missing:
            return
        if time.monotonic() > deadline:
            raise StartupError(f"simulated vehicle(s) {missing} sent no HEARTBEAT")
        await asyncio.sleep(0.05)
