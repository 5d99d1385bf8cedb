"""Fleet vehicles in the scene: what a fleet server (``--fleet``) sees of other edges'
vehicles, drawn with the local ones.

The interface is :class:`FleetScene`: the fleet view calls ``show(key, state, alive)`` with
each fleet vehicle's latest state (the JSON of GET /vehicles/{id}, as the edge published it)
and ``forget(key)`` when it leaves the fleet. Both only store the newest value under a lock,
from any thread; the scene draws what is pending at its own rate, so a fleet of a hundred
vehicles at 10 Hz costs the caller a dict write per state, and a scene that falls behind
skips states rather than queueing them.

A fleet vehicle is placed by its global position (WGS-84) relative to the scene's reference
point (the first vehicle's local origin) with pymap3d, and posed by its attitude; it is
drawn grey and labelled LOST while its edge's liveliness says it is gone.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping
from dataclasses import dataclass

import viser

from .frames import attitude_wxyz_enu, geodetic_offset_enu
from .models import LabelledModel
from .styling import Rgb, state_colour

LOST_COLOUR: Rgb = (90, 94, 102)


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def _section(state: Mapping[str, object], name: str) -> Mapping[str, object]:
    value = state.get(name)
    return value if isinstance(value, Mapping) else {}


@dataclass(frozen=True)
class FleetPose:
    """What the scene draws of one fleet vehicle, read from its state JSON."""

    key: str
    mav_type: str
    alive: bool
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    mode: str
    colour: Rgb
    # the vehicle's home (lat, lon, alt AMSL), when it has one: a reference for the scene
    home: tuple[float, float, float] | None

    @property
    def label(self) -> str:
        return f"{self.key} {'LOST' if not self.alive else self.mode}"


def fleet_pose(key: str, state: Mapping[str, object], alive: bool) -> FleetPose | None:
    """The pose of a fleet vehicle's state; None while it has no global position."""
    where = _section(state, "global")
    lat, lon, alt = (_number(where.get(k)) for k in ("lat_deg", "lon_deg", "alt_amsl_m"))
    if lat is None or lon is None or alt is None:
        return None
    attitude = _section(state, "attitude")
    roll, pitch, yaw = (_number(attitude.get(k)) or 0.0
                        for k in ("roll_deg", "pitch_deg", "yaw_deg"))
    home_section = _section(state, "home")
    home_values = [_number(home_section.get(k)) for k in ("lat_deg", "lon_deg", "alt_amsl_m")]
    home = (
        (home_values[0], home_values[1], home_values[2])
        if home_values[0] is not None and home_values[1] is not None
        and home_values[2] is not None else None
    )
    mode = str(state.get("mode") or "UNKNOWN")
    user_mode = state.get("user_mode")
    colour = state_colour(
        armed=bool(state.get("armed")), mode=mode,
        user_mode=user_mode if isinstance(user_mode, str) else None,
        system_status=str(state.get("system_status") or ""),
    ) if alive and state.get("connected", True) else LOST_COLOUR
    return FleetPose(
        key=key, mav_type=str(state.get("type") or "QUADROTOR"), alive=alive,
        lat_deg=lat, lon_deg=lon, alt_amsl_m=alt, roll_deg=roll, pitch_deg=pitch,
        yaw_deg=yaw, mode=mode, colour=colour, home=home,
    )


class FleetScene:
    """The fleet view's hook into the scene (thread-safe, latest wins)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pending: dict[str, FleetPose | None] = {}
        self._wanted = threading.Event()

    def show(self, key: str, state: Mapping[str, object], alive: bool = True) -> None:
        """The latest state of fleet vehicle ``key`` ("<edge>/<id>")."""
        pose = fleet_pose(key, state, alive)
        if pose is None:
            return
        with self._lock:
            self._pending[key] = pose
        self._wanted.set()

    def forget(self, key: str) -> None:
        """The vehicle left the fleet: remove it from the scene."""
        with self._lock:
            self._pending[key] = None
        self._wanted.set()

    def take(self) -> dict[str, FleetPose | None]:
        """What changed since the last call (None: removed)."""
        with self._lock:
            pending, self._pending = self._pending, {}
            self._wanted.clear()
        return pending


class FleetVehicleView(LabelledModel):
    """The scene nodes of one fleet vehicle: its model and a label."""

    def __init__(self, scene: viser.SceneApi, key: str, mav_type: str) -> None:
        super().__init__(scene, f"/fleet/{key}", mav_type, label=key)
        self.key = key
        self._label_text = key

    def update(self, pose: FleetPose, reference: tuple[float, float, float]) -> None:
        east, north, up = geodetic_offset_enu(
            pose.lat_deg, pose.lon_deg, pose.alt_amsl_m, *reference
        )
        self.position_enu = (round(east, 3), round(north, 3), round(up, 3))
        self.model.root.position = self.position_enu
        self.model.root.wxyz = attitude_wxyz_enu(pose.roll_deg, pose.pitch_deg, pose.yaw_deg)
        self.model.set_hull_colour(pose.colour)
        self.label.position = (east, north, up + 0.8)
        if pose.label != self._label_text:
            self._label_text = pose.label
            self.label.text = pose.label
