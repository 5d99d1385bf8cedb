"""The scene's north marker and compass rose: a ring around home on the ground, ticks every
30°, N/E/S/W labels and an arrow to north, so the heading of a vehicle reads off the scene
as off a map. The scene is ENU: north is +y, east is +x."""

from __future__ import annotations

import itertools
import math

import numpy as np
import viser

from .frames import Vec3

RING_RADIUS_M = 10.0
_RING_STEPS = 72
_TICK_EVERY_DEG = 30
_TICK_LENGTH_M = 1.0
_LABEL_RADIUS_M = RING_RADIUS_M + 1.6
_ARROW_LENGTH_M = RING_RADIUS_M + 3.0
_ARROW_HEAD_M = 1.2
# A hair above the ground grid, so the lines are never hidden in it.
_LIFT_M = 0.02
_RING_COLOUR = (190, 196, 208)
_NORTH_COLOUR = (231, 76, 60)
CARDINALS = {"N": 0.0, "E": 90.0, "S": 180.0, "W": 270.0}


def bearing_enu(bearing_deg: float, distance_m: float) -> Vec3:
    """The ground point at a compass bearing (0 north, 90 east) and distance, in ENU."""
    rad = math.radians(bearing_deg)
    return (distance_m * math.sin(rad), distance_m * math.cos(rad), _LIFT_M)


def rose_segments() -> np.ndarray:
    """The ring and its ticks as line segments, shape (n, 2, 3)."""
    ring = [bearing_enu(360.0 * k / _RING_STEPS, RING_RADIUS_M) for k in range(_RING_STEPS + 1)]
    segments = list(itertools.pairwise(ring))
    for bearing in range(0, 360, _TICK_EVERY_DEG):
        segments.append((bearing_enu(bearing, RING_RADIUS_M - _TICK_LENGTH_M),
                         bearing_enu(bearing, RING_RADIUS_M)))  # fmt: skip
    return np.array(segments, dtype=np.float32)


def north_arrow_segments() -> np.ndarray:
    """An arrow from the centre to north with a two-stroke head, shape (3, 2, 3)."""
    tip = bearing_enu(0.0, _ARROW_LENGTH_M)
    head_y = tip[1] - _ARROW_HEAD_M
    return np.array([
        (bearing_enu(0.0, 0.0), tip),
        (tip, (-_ARROW_HEAD_M * 0.6, head_y, _LIFT_M)),
        (tip, (_ARROW_HEAD_M * 0.6, head_y, _LIFT_M)),
    ], dtype=np.float32)  # fmt: skip


class CompassRose:
    """The rose's nodes under one frame, moved with the ground grid (to home)."""

    def __init__(self, scene: viser.SceneApi, name: str = "/compass") -> None:
        self.root = scene.add_frame(name, show_axes=False)
        scene.add_line_segments(
            f"{name}/rose", points=rose_segments(), colors=_RING_COLOUR,
            thickness=1.5, thickness_units="screen",
        )
        scene.add_line_segments(
            f"{name}/north", points=north_arrow_segments(), colors=_NORTH_COLOUR,
            thickness=3.0, thickness_units="screen",
        )
        self.labels = {
            letter: scene.add_label(
                f"{name}/{letter}", text=letter, position=bearing_enu(bearing, _LABEL_RADIUS_M)
            )
            for letter, bearing in CARDINALS.items()
        }

    def place(self, point: Vec3) -> None:
        self.root.position = point
