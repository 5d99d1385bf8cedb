"""Straight-line moves of a multicopter's autonomous modes, after PX4's PositionSmoothing in
FlightTaskAuto: the setpoint travels from where the move started to its target with a
jerk-limited acceleration (MPC_JERK_AUTO), at most MPC_ACC_HOR horizontally and
MPC_ACC_UP_MAX / MPC_ACC_DOWN_MAX vertically, at most the mode's horizontal speed and
MPC_Z_V_AUTO_UP / MPC_Z_V_AUTO_DN, braking to stop at the target. The position controller
tracks the moving setpoint with its velocity as feed-forward, so a long move takes PX4's time
(start and stop included) rather than a position loop's.
"""

from __future__ import annotations

import math

from sim.lib.params import ParamReader

# the move is over once the setpoint is this close to the target
ARRIVED_M = 0.02
# a target moved by more than this starts a new move
NEW_TARGET_M = 0.01


class StraightMove:
    def __init__(self, params: ParamReader) -> None:
        self._params = params
        self._target: list[float] | None = None
        self._origin = [0.0, 0.0, 0.0]
        self._direction = [0.0, 0.0, 0.0]
        self._length_m = 0.0
        self._travelled_m = 0.0
        self._speed_m_s = 0.0
        self._accel_m_s2 = 0.0
        self._speed_max = 0.0
        self._accel_max = 0.0

    def reset(self) -> None:
        self._target = None

    def setpoint(
        self, dt_s: float, position_ned_m: list[float], target_ned_m: list[float],
        xy_speed_m_s: float,
    ) -> tuple[list[float], list[float]]:
        """(position, velocity) setpoint now, for a move from where the vehicle was when the
        target was set."""
        if self._target is None or math.dist(self._target, target_ned_m) > NEW_TARGET_M:
            self._start(position_ned_m, target_ned_m, xy_speed_m_s)
        self._advance(dt_s)
        s, u = self._travelled_m, self._direction
        position = [self._origin[i] + u[i] * s for i in range(3)]
        velocity = [u[i] * self._speed_m_s for i in range(3)]
        return position, velocity

    def _start(self, position: list[float], target: list[float], xy_speed_m_s: float) -> None:
        p = self._params
        self._target = list(target)
        self._origin = list(position)
        delta = [target[i] - position[i] for i in range(3)]
        self._length_m = math.sqrt(sum(d * d for d in delta))
        self._direction = ([d / self._length_m for d in delta] if self._length_m > 1e-9
                           else [0.0, 0.0, 0.0])
        self._travelled_m = self._speed_m_s = self._accel_m_s2 = 0.0
        horizontal = math.hypot(self._direction[0], self._direction[1])
        vertical = self._direction[2]  # NED: negative climbs
        up = vertical < 0.0
        speed_z = p.get("MPC_Z_V_AUTO_UP") if up else p.get("MPC_Z_V_AUTO_DN")
        accel_z = p.get("MPC_ACC_UP_MAX") if up else p.get("MPC_ACC_DOWN_MAX")
        self._speed_max = min(_share(xy_speed_m_s, horizontal), _share(speed_z, abs(vertical)))
        self._accel_max = min(_share(p.get("MPC_ACC_HOR"), horizontal),
                              _share(accel_z, abs(vertical)))

    def _advance(self, dt_s: float) -> None:
        remaining = self._length_m - self._travelled_m
        if remaining <= ARRIVED_M or dt_s <= 0.0:
            if remaining <= ARRIVED_M:
                self._travelled_m, self._speed_m_s, self._accel_m_s2 = self._length_m, 0.0, 0.0
            return
        jerk = max(self._params.get("MPC_JERK_AUTO"), 0.1)
        a_max, v = max(self._accel_max, 0.1), self._speed_m_s
        braking_m = v * v / (2.0 * a_max) + v * a_max / (2.0 * jerk)
        wanted = self._speed_max if remaining > braking_m else 0.0
        target_accel = a_max if v < wanted else (-a_max if v > wanted else 0.0)
        step = jerk * dt_s
        self._accel_m_s2 += max(-step, min(step, target_accel - self._accel_m_s2))
        v = max(0.0, min(self._speed_max, v + self._accel_m_s2 * dt_s))
        if v == 0.0 and self._accel_m_s2 < 0.0:
            self._accel_m_s2 = 0.0
        self._speed_m_s = v
        self._travelled_m = min(self._length_m, self._travelled_m + v * dt_s)


def _share(limit: float, component: float) -> float:
    """The most along a direction whose component on an axis is `component` (0..1) when
    that axis allows `limit`."""
    return limit / component if component > 1e-6 else math.inf
