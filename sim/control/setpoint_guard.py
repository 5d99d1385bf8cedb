"""Make attitude and rates setpoints safe for the controllers.

In a trajectory setpoint NaN means "not controlled" and the controllers honour it. In an
attitude or rates setpoint a NaN or a degenerate quaternion would only poison integrators,
so it is replaced before use: NaN rates and thrusts become zero, an unusable quaternion
becomes "level at the current heading".
"""

from __future__ import annotations

import math

from sim.lib.numeric import finite_or, is_finite
from sim.lib.quat import quat_from_yaw, yaw_from_quat
from sim.lib.topics import AttitudeSetpoint, ControlSetpoint, RatesSetpoint, VehicleStateTruth


def _finite3(v: tuple[float, float, float]) -> tuple[float, float, float]:
    return (finite_or(v[0], 0.0), finite_or(v[1], 0.0), finite_or(v[2], 0.0))


def safe_setpoint(setpoint: ControlSetpoint, truth: VehicleStateTruth) -> ControlSetpoint:
    if isinstance(setpoint, RatesSetpoint):
        if all(is_finite(x) for x in (*setpoint.rates_rad_s, *setpoint.thrust_body)):
            return setpoint
        return RatesSetpoint(_finite3(setpoint.rates_rad_s), _finite3(setpoint.thrust_body))
    if isinstance(setpoint, AttitudeSetpoint):
        q = setpoint.q_wxyz
        norm = math.sqrt(sum(c * c for c in q)) if all(is_finite(c) for c in q) else 0.0
        thrust_ok = all(is_finite(x) for x in setpoint.thrust_body)
        if abs(norm - 1.0) < 1e-3 and thrust_ok:
            return setpoint
        if norm > 0.5:
            q_safe = (q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm)
        else:
            q_safe = quat_from_yaw(yaw_from_quat(truth.q_wxyz))
        return AttitudeSetpoint(q_safe, _finite3(setpoint.thrust_body))
    return setpoint
