"""Vehicle models drawn in the FLU body frame (nose +x, left +y, up +z), metres."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import viser
import viser.transforms as vtf

from .frames import Vec3
from .styling import Rgb, rotor_colour

_ROTOR_COUNTS = {"QUADROTOR": 4, "HEXAROTOR": 6, "OCTOROTOR": 8, "TRICOPTER": 3}
_VTOL_TYPES = frozenset(
    {"VTOL_FIXEDROTOR", "VTOL_TAILSITTER_QUADROTOR", "VTOL_TAILSITTER_DUOROTOR",
     "VTOL_TILTROTOR", "VTOL_TAILSITTER", "VTOL_TILTWING", "VTOL_RESERVED5"}
)
_FIXED_WING_TYPES = frozenset({"FIXED_WING", "FLAPPING_WING"})
_ROVER_TYPES = frozenset({"GROUND_ROVER", "SURFACE_BOAT"})
_ROTOR_DARK: Rgb = (60, 60, 70)


def model_kind(mav_type: str) -> str:
    """'multicopter', 'vtol', 'fixed_wing' or 'rover' for a MAV_TYPE name."""
    name = mav_type.upper().removeprefix("MAV_TYPE_")
    if name in _VTOL_TYPES or name.startswith("VTOL"):
        return "vtol"
    if name in _FIXED_WING_TYPES:
        return "fixed_wing"
    if name in _ROVER_TYPES:
        return "rover"
    return "multicopter"


def rotor_count(mav_type: str) -> int:
    return _ROTOR_COUNTS.get(mav_type.upper().removeprefix("MAV_TYPE_"), 4)


def rotor_positions_flu(count: int, arm_m: float) -> list[tuple[float, float]]:
    """Rotor centres (forward, left), an X layout like PX4's quad-x / hex-x / octo-x."""
    offset = math.pi / count
    return [
        (arm_m * math.cos(offset + 2 * math.pi * i / count),
         arm_m * math.sin(offset + 2 * math.pi * i / count))
        for i in range(count)
    ]


@dataclass
class VehicleModel:
    """Scene nodes of one vehicle's model under `root` (a frame whose pose is the attitude)."""

    root: viser.FrameHandle
    hull: list[viser.BoxHandle] = field(default_factory=list)
    rotors: list[viser.CylinderHandle] = field(default_factory=list)
    mc_group: viser.FrameHandle | None = None
    fw_group: viser.FrameHandle | None = None
    _hull_colour: Rgb | None = None
    _rotor_shades: list[int] = field(default_factory=list)
    _fixed_wing_shown: bool | None = None

    def set_hull_colour(self, colour: Rgb) -> None:
        if colour == self._hull_colour:
            return
        self._hull_colour = colour
        for part in self.hull:
            part.color = colour

    def set_rotor_outputs(self, outputs: tuple[float, ...]) -> None:
        """Rotor discs glow with their motor output; only changed shades are resent."""
        for i, rotor in enumerate(self.rotors):
            value = outputs[i] if i < len(outputs) else 0.0
            level = min(1.0, max(0.0, value)) * 20
            shade = round(level)
            # a whole shade away from the one shown: an output hovering on a boundary does not
            # flicker between two (each change is a redraw in every browser)
            if i < len(self._rotor_shades) and abs(level - self._rotor_shades[i]) < 1.0:
                continue
            while len(self._rotor_shades) <= i:
                self._rotor_shades.append(-1)
            self._rotor_shades[i] = shade
            rotor.color = rotor_colour(shade / 20.0)

    def show_fixed_wing(self, fixed_wing: bool) -> None:
        """VTOL: lift rotors fold away in FW; the wing dominates."""
        if self.mc_group is None or self._fixed_wing_shown == fixed_wing:
            return
        self._fixed_wing_shown = fixed_wing
        self.mc_group.visible = not fixed_wing


def _add_multicopter(scene: viser.SceneApi, base: str, count: int, model: VehicleModel) -> None:
    arm_m = 0.45
    model.hull.append(scene.add_box(f"{base}/hub", dimensions=(0.3, 0.2, 0.1)))
    # The nose stays white so the heading reads whatever the state colour.
    scene.add_box(f"{base}/nose", dimensions=(0.12, 0.06, 0.06), position=(0.2, 0.0, 0.0),
                  color=(255, 255, 255))
    for i, (x, y) in enumerate(rotor_positions_flu(count, arm_m)):
        model.hull.append(
            scene.add_box(
                f"{base}/arm{i}", dimensions=(arm_m, 0.04, 0.03),
                position=(x / 2, y / 2, 0.0),
                wxyz=vtf.SO3.from_z_radians(math.atan2(y, x)).wxyz,
            )
        )
        model.rotors.append(
            scene.add_cylinder(
                f"{base}/rotor{i}", radius=0.2, height=0.02, color=_ROTOR_DARK,
                position=(x, y, 0.05), radial_segments=20,
            )
        )


def _add_fixed_wing(scene: viser.SceneApi, base: str, model: VehicleModel) -> None:
    model.hull.append(scene.add_box(f"{base}/fuselage", dimensions=(1.2, 0.14, 0.14)))
    model.hull.append(
        scene.add_box(f"{base}/wing", dimensions=(0.3, 2.0, 0.03), position=(0.1, 0.0, 0.02))
    )
    model.hull.append(
        scene.add_box(f"{base}/tailplane", dimensions=(0.18, 0.6, 0.02), position=(-0.55, 0.0, 0.0))
    )
    model.hull.append(
        scene.add_box(f"{base}/fin", dimensions=(0.18, 0.02, 0.25), position=(-0.55, 0.0, 0.12))
    )
    scene.add_box(f"{base}/nose", dimensions=(0.1, 0.1, 0.1), position=(0.62, 0.0, 0.0),
                  color=(255, 255, 255))


def _add_rover(scene: viser.SceneApi, base: str, model: VehicleModel) -> None:
    model.hull.append(scene.add_box(f"{base}/chassis", dimensions=(0.6, 0.4, 0.15),
                                    position=(0.0, 0.0, 0.12)))
    scene.add_box(f"{base}/nose", dimensions=(0.1, 0.3, 0.1), position=(0.3, 0.0, 0.15),
                  color=(255, 255, 255))


def build_model(scene: viser.SceneApi, name: str, mav_type: str) -> VehicleModel:
    root = scene.add_frame(name, show_axes=False)
    model = VehicleModel(root=root)
    kind = model_kind(mav_type)
    if kind == "multicopter":
        _add_multicopter(scene, name, rotor_count(mav_type), model)
    elif kind == "fixed_wing":
        _add_fixed_wing(scene, name, model)
    elif kind == "rover":
        _add_rover(scene, name, model)
    else:
        model.mc_group = scene.add_frame(f"{name}/mc", show_axes=False)
        model.fw_group = scene.add_frame(f"{name}/fw", show_axes=False)
        _add_fixed_wing(scene, f"{name}/fw", model)
        _add_multicopter(scene, f"{name}/mc", 4, model)
    return model


class LabelledModel:
    """A vehicle's nodes under one frame at ``base``: its model and a label above it."""

    def __init__(self, scene: viser.SceneApi, base: str, mav_type: str, label: str) -> None:
        self.mav_type = mav_type
        self.position_enu: Vec3 | None = None
        self._root = scene.add_frame(base, show_axes=False)
        self.model: VehicleModel = build_model(scene, f"{base}/body", mav_type)
        self.label = scene.add_label(f"{base}/label", text=label, anchor="bottom-center")

    def remove(self) -> None:
        """Removing the parent node removes every child node of this vehicle."""
        self._root.remove()
