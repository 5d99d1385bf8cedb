"""A vehicle's recent path, fading with age."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .frames import Vec3
from .styling import Rgb, blend

TRAIL_SPAN_S = 60.0
_MIN_SPACING_S = 0.2
_MIN_STEP_M = 0.05


@dataclass(eq=False)
class Trail:
    """Samples at most every 0.2 s (and only when the vehicle moved), kept for ``span_s``."""

    span_s: float = TRAIL_SPAN_S
    _points: deque[tuple[float, Vec3]] = field(default_factory=deque, init=False, repr=False)

    def __len__(self) -> int:
        return len(self._points)

    def add(self, time_s: float, point: Vec3) -> bool:
        if self._points:
            last_t, last_p = self._points[-1]
            moved = max(abs(a - b) for a, b in zip(point, last_p, strict=True))
            if time_s - last_t < _MIN_SPACING_S or moved < _MIN_STEP_M:
                self._drop_old(time_s)
                return False
        self._points.append((time_s, point))
        self._drop_old(time_s)
        return True

    def _drop_old(self, now_s: float) -> None:
        while self._points and now_s - self._points[0][0] > self.span_s:
            self._points.popleft()

    def segments(
        self, now_s: float, colour: Rgb, background: Rgb
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
        """Line segments (N, 2, 3) and per-vertex colours that fade to `background` at 60 s."""
        pts = list(self._points)
        n = max(0, len(pts) - 1)
        points = np.zeros((n, 2, 3), dtype=np.float32)
        colours = np.zeros((n, 2, 3), dtype=np.uint8)
        for i in range(n):
            for j in (0, 1):
                t, p = pts[i + j]
                points[i, j] = p
                colours[i, j] = blend(colour, background, 1.0 - (now_s - t) / self.span_s)
        return points, colours
