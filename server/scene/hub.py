"""SceneHub: the viser server, fed with vehicle snapshots pushed by a state source (the
app's state publishers), and its place in the app."""

from __future__ import annotations

import asyncio
import contextlib
import io
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

import numpy as np
import viser
from fastapi import FastAPI

from server.link.codec.aio import cancel_and_wait
from skyhelm_wire.messages import SceneClickMessage

from .compass import CompassRose
from .fleet_view import FleetPose, FleetScene, FleetVehicleView
from .frames import Vec3, enu_to_geodetic, geodetic_offset_enu, ray_hits_plane_z
from .proxy import SceneProxy
from .vehicle_view import DEFAULT_PIXEL_M, VehicleView

if TYPE_CHECKING:
    from server.link import VehicleState

_log = logging.getLogger(__name__)

# With nobody watching, the scene still follows (a client that connects gets the current
# picture at once) but at a trickle, to leave the CPU to the streamer.
_IDLE_RATE_HZ = 2.0
# Vehicles updated in one go before the loop gets a turn: one update costs ~0.5 ms, so 50
# vehicles at once held the loop (and the setpoint streams on it) ~25 ms.
_VEHICLES_PER_SLICE = 8
_FOLLOW_OFF = "off"
_FLEET_PREFIX = "fleet "
# fleet vehicles arrive at most at 10 Hz each (state/fast); the scene draws them in batches
_FLEET_RATE_HZ = 10.0
_CAMERA_OFFSET_ENU = np.array([-6.0, -6.0, 4.0])
# The scene panel's title: viser's own says "Connected" (its socket to this server), which a
# pilot reads as the vehicle. It says what the view shows instead, and which link is lost.
SCENE_LABEL = "3D view"
# Updates are not wrapped in viser's atomic(): viser sends nothing while any atomic block
# is open and looks again only 1/60 s after one closes, so on a busy machine, where an
# update takes ~25 ms and the next follows soon after, the scene's changes were held back
# (one message for every four updates; in a loaded run none for 17 s, the vehicle armed
# meanwhile). A frame that shows a vehicle's label a message behind its model is harmless.
# Finer than this the model never moves, however close a camera is.
_PIXEL_MIN_M = 0.002


class StateWatch(Protocol):
    async def next_states(self) -> list[VehicleState]:
        """Wait for, then return, the newest state of each vehicle that changed since the
        last call: latest wins, so a scene that falls behind skips states, never queues."""
        ...

    def close(self) -> None: ...


class StateSource(Protocol):
    def watch_states(self, rate_hz: float) -> StateWatch:
        """Every vehicle's state, now and discovered later, at most rate_hz per vehicle."""
        ...


def local_origin(state: VehicleState) -> tuple[float, float, float] | None:
    """Geodetic point of the vehicle's local NED origin: reported by GPS_GLOBAL_ORIGIN, or
    else worked back from home, whose position PX4 gives both ways."""
    if state.origin is not None:
        return (state.origin.lat_deg, state.origin.lon_deg, state.origin.alt_amsl_m)
    home = state.home
    if home is None:
        return None
    return enu_to_geodetic(-home.east_m, -home.north_m, home.down_m,
                           home.lat_deg, home.lon_deg, home.alt_amsl_m)


class SceneHub:
    def __init__(self, *, host: str = "127.0.0.1", port: int = 0,
                 max_rate_hz: float = 30.0) -> None:
        self._host = host
        self._port = port
        self.max_rate_hz = max_rate_hz
        self._server: viser.ViserServer | None = None
        self._task: asyncio.Task[None] | None = None
        self._views: dict[int, VehicleView] = {}
        self._reference: tuple[float, float, float] | None = None
        self._ground_z = 0.0
        self._click: SceneClickMessage | None = None
        self._click_lock = threading.Lock()
        self._follow: viser.GuiDropdownHandle[str] | None = None
        self._followed_at: np.ndarray | None = None
        self._placed_clients: set[int] = set()
        self._grid_at: Vec3 | None = None
        self._grid: viser.GridHandle | None = None
        self._compass: CompassRose | None = None
        self._proxy: SceneProxy | None = None
        self.updates_applied = 0
        # a fleet server's other-edge vehicles (fleet_view.py): its fleet view feeds this
        self.fleet = FleetScene()
        self._fleet_views: dict[str, FleetVehicleView] = {}
        self._fleet_task: asyncio.Task[None] | None = None
        self._links_lost: dict[int, bool] = {}
        self._label: str | None = None
        # Told of every click (in viser's thread), after it is stored.
        self.on_click: Callable[[SceneClickMessage], None] | None = None

    @property
    def port(self) -> int:
        if self._server is None:
            raise RuntimeError("SceneHub is not started")
        return int(self._server.get_port())

    @property
    def last_click(self) -> SceneClickMessage | None:
        return self._click

    async def start(self, states: StateSource | None = None) -> None:
        """Serve the scene, drawing every vehicle states pushes (none without it)."""
        if self._server is not None:
            return
        # viser prints a banner advertising its private, tokenless port: users should open
        # only the app's URL, so the banner is swallowed. Construction takes a few ms, so it
        # runs on the loop.
        with contextlib.redirect_stdout(io.StringIO()):
            self._server = viser.ViserServer(host=self._host, port=self._port, verbose=False)
        self._set_up_scene(self._server)
        if states is not None:
            self._task = asyncio.create_task(self._follow_states(states), name="scene-hub")
        self._fleet_task = asyncio.create_task(self._follow_fleet(), name="scene-fleet")

    async def stop(self) -> None:
        await cancel_and_wait(self._task)
        await cancel_and_wait(self._fleet_task)
        self._task = self._fleet_task = None
        if self._server is not None:
            server, self._server = self._server, None
            with contextlib.redirect_stdout(io.StringIO()):
                await asyncio.to_thread(server.stop)
        self._views.clear()
        self._fleet_views.clear()

    def mount(self, app: FastAPI, *, path: str = "/scene",
              check_token: Callable[[str | None], bool]) -> None:
        self._proxy = SceneProxy(lambda: self.port, check_token)
        self._proxy.mount(app, path, {"click": self._click_json, "status": self.status})

    def status(self) -> dict[str, object]:
        return {
            "running": self._server is not None,
            "viser_clients": len(self._server.get_clients()) if self._server else 0,
            "proxied_sockets": self._proxy.open_sockets if self._proxy else 0,
            "vehicles": sorted(self._views),
            "fleet_vehicles": sorted(self._fleet_views),
            "max_rate_hz": self.max_rate_hz,
            "updates_applied": self.updates_applied,
        }

    def _click_json(self) -> dict[str, object]:
        click = self._click
        return {"seq": 0} if click is None else click.model_dump(exclude={"type"})

    def _set_up_scene(self, server: viser.ViserServer) -> None:
        self._label = None
        self._show_label(server)
        server.scene.set_up_direction("+z")
        server.scene.world_axes.visible = False
        # no environment map (viser's default HDRI, prefiltered on the client: software
        # WebGL spent 60 % of a core on it for ~40 s after the view showed); a sky light
        # lights the models instead
        server.scene.configure_environment_map(hdri=None)
        server.scene.add_light_hemisphere("/sky", sky_color=(255, 255, 255),
                                          ground_color=(90, 90, 100), intensity=2.0)
        server.initial_camera.position = tuple(_CAMERA_OFFSET_ENU)
        server.initial_camera.look_at = (0.0, 0.0, 0.0)
        self._follow = server.gui.add_dropdown("Follow", options=(_FOLLOW_OFF,),
                                               initial_value=_FOLLOW_OFF)
        self._grid = server.scene.add_grid(
            "/ground", width=200.0, height=200.0, cell_size=1.0, section_size=10.0,
            cell_color=(70, 74, 82), section_color=(110, 116, 128), plane="xy",
        )
        self._compass = CompassRose(server.scene)
        self._click_marker = server.scene.add_icosphere(
            "/click", radius=0.3, color=(255, 255, 255), opacity=0.6, visible=False
        )
        server.scene.on_click()(self._on_click)

    def _on_click(self, event: viser.SceneClickEvent) -> None:
        self.record_click(event.ray_origin, event.ray_direction)

    def record_click(self, ray_origin: Vec3, ray_direction: Vec3) -> None:
        """A click ray (runs in viser's thread): stores where it meets the ground and marks it."""
        hit = ray_hits_plane_z(ray_origin, ray_direction, self._ground_z)
        if hit is None:
            return
        lat = lon = alt = None
        if self._reference is not None:
            lat, lon, alt = enu_to_geodetic(hit[0], hit[1], hit[2], *self._reference)
        with self._click_lock:
            seq = 1 if self._click is None else self._click.seq + 1
            click = SceneClickMessage(
                type="scene_click", seq=seq, time_s=time.time(),
                east_m=hit[0], north_m=hit[1], up_m=hit[2],
                lat_deg=lat, lon_deg=lon, alt_amsl_m=alt,
            )
            self._click = click
        self._click_marker.position = hit
        self._click_marker.visible = True
        if self.on_click is not None:
            self.on_click(click)

    async def _follow_states(self, states: StateSource) -> None:
        # Unwatched, the scene asks for states at the idle rate only: every vehicle's
        # publisher then takes its snapshots that rarely too (with 50 vehicles, 30 Hz each
        # cost ~15 % of a core for a scene nobody saw). Watched again, it asks for the full
        # rate, and the new watch brings every vehicle's current state at once.
        watched = self._watched()
        watch = states.watch_states(self.max_rate_hz if watched else _IDLE_RATE_HZ)
        loop = asyncio.get_running_loop()
        try:
            while True:
                if self._watched() != watched:
                    watched = not watched
                    watch.close()
                    watch = states.watch_states(self.max_rate_hz if watched else _IDLE_RATE_HZ)
                changed = await watch.next_states()
                for first in range(0, len(changed), _VEHICLES_PER_SLICE):
                    if first:
                        await asyncio.sleep(0)
                    try:
                        self._apply_states(changed[first:first + _VEHICLES_PER_SLICE],
                                           loop.time())
                    except Exception:
                        # A bad snapshot must not kill the scene for the whole session.
                        _log.exception("scene update failed")
        finally:
            watch.close()

    async def _follow_fleet(self) -> None:
        while True:
            await asyncio.sleep(1.0 / _FLEET_RATE_HZ)
            changes = self.fleet.take()
            if not changes or self._server is None:
                continue
            try:
                self._apply_fleet(self._server, changes)
            except Exception:
                _log.exception("scene fleet update failed")

    def _apply_fleet(self, server: viser.ViserServer, changes: dict[str, FleetPose | None]) -> None:
        listed = False
        for key, pose in changes.items():
            view = self._fleet_views.get(key)
            if pose is None or (view is not None and view.mav_type != pose.mav_type):
                if view is not None:
                    view.remove()
                    del self._fleet_views[key]
                    listed = True
                if pose is None:
                    continue
            if self._reference is None:
                # no local vehicle yet: the first fleet vehicle's home (or itself) is 0,0,0
                self._reference = pose.home or (pose.lat_deg, pose.lon_deg, pose.alt_amsl_m)
            view = self._fleet_views.get(key)
            if view is None:
                view = self._fleet_views[key] = FleetVehicleView(server.scene, key,
                                                                 pose.mav_type)
                listed = True
            view.update(pose, self._reference)
            self.updates_applied += 1
        if listed:
            self._refresh_follow_options()
        self._follow_camera(server)

    def _watched(self) -> bool:
        if self._proxy is not None and self._proxy.open_sockets > 0:
            return True
        return self._server is not None and bool(self._server.get_clients())

    def _apply_states(self, states: list[VehicleState], now_s: float) -> None:
        server = self._server
        if server is None:
            return
        for state in states:
            self._apply(server, state, now_s)
        self._follow_camera(server)
        self._show_label(server)

    def _show_label(self, server: viser.ViserServer) -> None:
        """The panel's title: what the view shows, and any vehicle whose link is lost."""
        lost = sorted(sysid for sysid, gone in self._links_lost.items() if gone)
        label = SCENE_LABEL if not lost else (
            f"{SCENE_LABEL} · link lost: vehicle {', '.join(str(s) for s in lost)}"
        )
        if label != self._label:
            self._label = label
            server.gui.set_panel_label(label)

    @property
    def panel_label(self) -> str | None:
        """The scene panel's title as last sent (for the tests)."""
        return self._label

    def pixel_m(self, server: viser.ViserServer, point: Vec3) -> float:
        """What one pixel spans at ``point`` in the closest view of any client (a
        default before any client told its camera): finer changes do not show."""
        best: float | None = None
        for client in server.get_clients().values():
            camera = client.camera
            height = camera.image_height
            if height <= 0:
                continue
            distance = float(np.linalg.norm(np.asarray(camera.position) - np.asarray(point)))
            size = 2.0 * distance * math.tan(camera.fov / 2.0) / height
            best = size if best is None else min(best, size)
        return DEFAULT_PIXEL_M if best is None else max(best, _PIXEL_MIN_M)

    def _apply(self, server: viser.ViserServer, state: VehicleState, now_s: float) -> None:
        view = self._views.get(state.sysid)
        if view is None or view.mav_type != state.mav_type:
            if view is not None:
                view.remove()
            view = VehicleView(server.scene, state.sysid, state.mav_type)
            self._views[state.sysid] = view
            self._refresh_follow_options()
        self._links_lost[state.sysid] = state.connected is False
        offset = self._offset_enu(state)
        point = view.position_enu if view.position_enu is not None else offset
        view.update(state, offset, now_s, self.pixel_m(server, point))
        self.updates_applied += 1
        if state.home is not None and state.sysid == min(self._views):
            self._place_grid(view, state)

    def _offset_enu(self, state: VehicleState) -> Vec3:
        """Each vehicle reports NED around its own origin; the scene uses the first one's."""
        here = local_origin(state)
        if here is None:
            return (0.0, 0.0, 0.0)
        if self._reference is None:
            self._reference = here
        return geodetic_offset_enu(*here, *self._reference)

    def _place_grid(self, view: VehicleView, state: VehicleState) -> None:
        home = view.home_marker.position
        point: Vec3 = (float(home[0]), float(home[1]), float(home[2]))
        if self._grid is None or (
            self._grid_at is not None and max(abs(a - b) for a, b in zip(point, self._grid_at,
                                                                          strict=True)) < 0.5
        ):
            return
        self._grid_at = point
        self._grid.position = point
        if self._compass is not None:
            self._compass.place(point)
        self._ground_z = point[2]

    def _refresh_follow_options(self) -> None:
        if self._follow is None:
            return
        first_vehicle = self._follow.value == _FOLLOW_OFF and len(self._views) == 1
        self._follow.options = (
            _FOLLOW_OFF, *(f"vehicle {s}" for s in sorted(self._views)),
            *(f"{_FLEET_PREFIX}{key}" for key in sorted(self._fleet_views)),
        )
        if first_vehicle:
            # viser's setter is typed on a generic base that mypy sees as read-only.
            self._follow.value = f"vehicle {min(self._views)}"  # type: ignore[misc]

    def _followed_position(self, choice: str) -> Vec3 | None:
        if choice.startswith(_FLEET_PREFIX):
            fleet_view = self._fleet_views.get(choice.removeprefix(_FLEET_PREFIX))
            return None if fleet_view is None else fleet_view.position_enu
        view = self._views.get(int(choice.split()[-1]))
        return None if view is None else view.position_enu

    def _follow_camera(self, server: viser.ViserServer) -> None:
        """Moves every client's camera with the followed vehicle, keeping the user's view angle."""
        if self._follow is None or self._follow.value == _FOLLOW_OFF:
            self._followed_at = None
            return
        position = self._followed_position(self._follow.value)
        if position is None:
            return
        target = np.array(position)
        previous = self._followed_at
        self._followed_at = target
        moved = previous is None or float(np.abs(target - previous).max()) >= 0.01
        clients = server.get_clients()
        self._placed_clients &= set(clients)
        for client_id, client in clients.items():
            camera = client.camera
            if client_id not in self._placed_clients:
                self._placed_clients.add(client_id)
                offset = _CAMERA_OFFSET_ENU
            elif moved:
                offset = np.asarray(camera.position) - np.asarray(camera.look_at)
            else:
                continue
            # viser moves look_at along with position, so position goes first (not in an
            # atomic block: see the note on atomic() above; between the two messages the
            # view is off by one update's travel, for a frame at most).
            camera.position = target + offset
            camera.look_at = target
