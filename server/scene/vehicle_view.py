"""The scene nodes of one vehicle, updated from its VehicleState snapshots."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import viser

from .frames import Vec3, attitude_wxyz_enu, ned_to_enu
from .models import LabelledModel, model_kind
from .styling import Rgb, state_colour
from .trail import Trail

if TYPE_CHECKING:
    from server.link import HomeState, PositionNedState, VehicleState

SCENE_BACKGROUND: Rgb = (30, 33, 40)
_TRAIL_REDRAW_S = 0.5
_VELOCITY_LOOKAHEAD_S = 2.0
_SETPOINT_COLOUR: Rgb = (241, 196, 15)
_TARGET_COLOUR: Rgb = (230, 126, 34)
_HOME_COLOUR: Rgb = (236, 240, 241)
_RTL_COLOUR: Rgb = (231, 76, 60)
# What one pixel of the view spans when no client told its camera yet.
DEFAULT_PIXEL_M = 0.01
# How far the model's farthest point (a rotor tip, a wing tip) is from its centre: an
# attitude change that moves it less than a pixel does not show.
_MODEL_REACH_M = 0.6


def _finite(*values: float | None) -> bool:
    return all(v is not None and math.isfinite(v) for v in values)


def _shift(point: Vec3, offset: Vec3) -> Vec3:
    return (point[0] + offset[0], point[1] + offset[1], point[2] + offset[2])


def _ned(point: PositionNedState | HomeState | None) -> Vec3 | None:
    """(north, east, down) of a reported point, None when absent or not finite."""
    if point is None or not _finite(point.north_m, point.east_m, point.down_m):
        return None
    return (point.north_m, point.east_m, point.down_m)


def setpoint_point_ned(
    setpoint: Mapping[str, object] | None, position_ned: Vec3 | None
) -> Vec3 | None:
    """Where the streamed setpoint points: its position, or 2 s ahead along its velocity."""
    if not setpoint:
        return None

    def num(key: str) -> float | None:
        value = setpoint.get(key)
        return float(value) if isinstance(value, int | float) else None

    n, e, d = num("north_m"), num("east_m"), num("down_m")
    if _finite(n, e, d):
        return (n or 0.0, e or 0.0, d or 0.0)
    vn, ve, vd = num("north_m_s"), num("east_m_s"), num("down_m_s")
    if position_ned is not None and _finite(vn, ve):
        k = _VELOCITY_LOOKAHEAD_S
        return (position_ned[0] + k * (vn or 0.0), position_ned[1] + k * (ve or 0.0),
                position_ned[2] + k * (vd if vd is not None and math.isfinite(vd) else 0.0))
    return None


def rtl_path_enu(vehicle: Vec3, home: Vec3) -> list[Vec3]:
    """Climb-if-lower, fly over home at that altitude, descend: the shape of PX4's return."""
    cruise_z = max(vehicle[2], home[2] + 1.0)
    return [vehicle, (vehicle[0], vehicle[1], cruise_z), (home[0], home[1], cruise_z), home]


def _polyline_segments(points: list[Vec3]) -> np.ndarray:
    return np.array([[points[i], points[i + 1]] for i in range(len(points) - 1)], dtype=np.float32)


def _rounded(values: tuple[float, ...], digits: int = 3) -> tuple[float, ...]:
    return tuple(round(v, digits) for v in values)


def moved_beyond(shown: Vec3 | None, point: Vec3, pixel_m: float) -> bool:
    """Whether ``point`` is more than a pixel away from where the model is ``shown``."""
    return shown is None or max(abs(a - b) for a, b in zip(point, shown, strict=True)) > pixel_m


def turned_beyond(shown: tuple[float, ...] | None, wxyz: tuple[float, ...],
                  pixel_m: float) -> bool:
    """Whether the attitude ``wxyz`` turns the model's tips more than a pixel from ``shown``."""
    if shown is None:
        return True
    dot = min(1.0, abs(sum(a * b for a, b in zip(wxyz, shown, strict=True))))
    return 2.0 * math.acos(dot) * _MODEL_REACH_M > pixel_m


class _Assigner:
    """Sets a node's property only when its value changed: every set is a message to every
    watching browser, and most of a hovering vehicle's scene does not change."""

    def __init__(self) -> None:
        self._last: dict[tuple[int, str], object] = {}

    def __call__(self, handle: object, name: str, value: object) -> None:
        key = (id(handle), name)
        if key in self._last and self._last[key] == value:
            return
        self._last[key] = value
        setattr(handle, name, value)


class _Polyline:
    """A line-segment node that can be emptied (viser needs at least one segment)."""

    def __init__(self, scene: viser.SceneApi, name: str, colour: Rgb, thickness: float) -> None:
        self._colour = np.array(colour, dtype=np.uint8)
        self._shown: list[tuple[float, ...]] = []
        self._handle = scene.add_line_segments(
            name, points=np.zeros((1, 2, 3), dtype=np.float32), colors=colour,
            thickness=thickness, thickness_units="screen", visible=False,
        )

    def show(self, points: list[Vec3]) -> None:
        rounded = [_rounded(p) for p in points]
        if self._handle.visible and rounded == self._shown:
            return  # the same line: nothing sent, nothing redrawn
        self._shown = rounded
        segments = _polyline_segments(points)
        self._handle.points = segments
        self._handle.colors = np.broadcast_to(self._colour, segments.shape).astype(np.uint8)
        self._handle.visible = True

    def hide(self) -> None:
        if self._handle.visible:
            self._handle.visible = False

    @property
    def visible(self) -> bool:
        return bool(self._handle.visible)


class VehicleView(LabelledModel):
    def __init__(self, scene: viser.SceneApi, sysid: int, mav_type: str) -> None:
        base = f"/vehicles/{sysid}"
        super().__init__(scene, base, mav_type, label=f"{sysid}")
        self.sysid = sysid
        self._set = _Assigner()
        self._kind = model_kind(mav_type)
        self.trail = Trail()
        self._trail_handle = scene.add_line_segments(
            f"{base}/trail", points=np.zeros((1, 2, 3), dtype=np.float32), colors=(0, 0, 0),
            thickness=2.0, thickness_units="screen", visible=False,
        )
        self._trail_drawn_s = -math.inf
        self.setpoint_marker = scene.add_icosphere(
            f"{base}/setpoint", radius=0.15, color=_SETPOINT_COLOUR, visible=False
        )
        self.setpoint_line = _Polyline(scene, f"{base}/setpoint_line", _SETPOINT_COLOUR, 1.5)
        self.target_marker = scene.add_icosphere(
            f"{base}/target", radius=0.25, color=_TARGET_COLOUR, visible=False, opacity=0.8
        )
        self.home_marker = scene.add_cylinder(
            f"{base}/home", radius=0.5, height=0.05, color=_HOME_COLOUR, visible=False
        )
        self.home_label = scene.add_label(f"{base}/home/label", text="H", position=(0, 0, 0.3))
        self.rtl_path = _Polyline(scene, f"{base}/rtl", _RTL_COLOUR, 2.5)
        # where the model is drawn: moved (and turned) only by what a pixel of the view shows
        self._shown_position: Vec3 | None = None
        self._shown_wxyz: tuple[float, ...] | None = None

    def update(self, state: VehicleState, offset_enu: Vec3, now_s: float,
               pixel_m: float = DEFAULT_PIXEL_M) -> None:
        """Sets the nodes from a state; the model moves (and turns) only when the change is
        more than ``pixel_m``, what one pixel of the closest view spans at the vehicle: each
        change is a message to every browser and a redraw there."""
        colour = state_colour(
            armed=state.armed, mode=state.mode, user_mode=state.user_mode,
            system_status=state.system_status,
        )
        self.model.set_hull_colour(colour)
        self.model.set_rotor_outputs(tuple(state.actuator_outputs))
        if self._kind == "vtol":
            self.model.show_fixed_wing(state.vtol_state in ("FW", "TRANSITION_TO_FW"))
        mode_text = state.mode if state.user_mode in (None, state.mode) else (
            f"{state.mode} (wants {state.user_mode})"
        )
        self._set(self.label, "text", f"{state.sysid} {mode_text}")

        position_ned: Vec3 | None = None
        if state.position_ned is not None:
            p = state.position_ned
            position_ned = (p.north_m, p.east_m, p.down_m)
            self.position_enu = _shift(ned_to_enu(*position_ned), offset_enu)
            if moved_beyond(self._shown_position, self.position_enu, pixel_m):
                self._shown_position = self.position_enu
                self._set(self.model.root, "position", _rounded(self.position_enu))
                self._set(self.label, "position",
                          _rounded(_shift(self.position_enu, (0.0, 0.0, 0.8))))
            if self.trail.add(now_s, self.position_enu) or now_s - self._trail_drawn_s > 5.0:
                self._redraw_trail(now_s, colour)
        if state.attitude is not None:
            a = state.attitude
            wxyz = tuple(attitude_wxyz_enu(a.roll_deg, a.pitch_deg, a.yaw_deg))
            if turned_beyond(self._shown_wxyz, wxyz, pixel_m):
                self._shown_wxyz = wxyz
                self._set(self.model.root, "wxyz", _rounded(wxyz, 5))

        self._update_setpoint(state, position_ned, offset_enu)
        home_enu = self._update_home(state, offset_enu)
        self._update_target(state, offset_enu)
        if state.mode == "RTL" and home_enu is not None and self._shown_position is not None:
            self.rtl_path.show(rtl_path_enu(self._shown_position, home_enu))
        else:
            self.rtl_path.hide()

    def _redraw_trail(self, now_s: float, colour: Rgb) -> None:
        if now_s - self._trail_drawn_s < _TRAIL_REDRAW_S or len(self.trail) < 2:
            return
        self._trail_drawn_s = now_s
        points, colours = self.trail.segments(now_s, colour, SCENE_BACKGROUND)
        self._trail_handle.points = points
        self._trail_handle.colors = colours
        self._trail_handle.visible = True

    def _place(self, marker: object, point_ned: Vec3 | None, offset_enu: Vec3) -> Vec3 | None:
        """Show ``marker`` at a NED point (hide it without one); the point in the scene."""
        if point_ned is None:
            self._set(marker, "visible", False)
            return None
        point_enu = _shift(ned_to_enu(*point_ned), offset_enu)
        self._set(marker, "position", _rounded(point_enu))
        self._set(marker, "visible", True)
        return point_enu

    def _update_setpoint(self, state: VehicleState, position_ned: Vec3 | None,
                         offset_enu: Vec3) -> None:
        point_ned = setpoint_point_ned(state.setpoint, position_ned)
        if point_ned is None and state.mode == "OFFBOARD":
            point_ned = _ned(state.target_ned)
        if self.position_enu is None:
            point_ned = None
        point_enu = self._place(self.setpoint_marker, point_ned, offset_enu)
        if point_enu is None or self._shown_position is None:
            self.setpoint_line.hide()
        else:
            self.setpoint_line.show([self._shown_position, point_enu])

    def _update_home(self, state: VehicleState, offset_enu: Vec3) -> Vec3 | None:
        return self._place(self.home_marker, _ned(state.home), offset_enu)

    def _update_target(self, state: VehicleState, offset_enu: Vec3) -> None:
        """In Hold (where DO_REPOSITION flies) PX4's own position target is the goal."""
        target_ned = _ned(state.target_ned) if state.mode == "HOLD" else None
        self._place(self.target_marker, target_ned, offset_enu)
