"""Multicopter attitude control after PX4's mc_att_control (AttitudeControl).

Quaternion error with reduced (tilt-first) attitude: roll and pitch are prioritised over
yaw (MC_YAW_WEIGHT); the output is a body-rate setpoint for `sim.control.mc_rate_control`.
"""

from __future__ import annotations

import functools
import math

from sim.lib.numeric import clamp, is_finite
from sim.lib.params import ParamReader, param_or
from sim.lib.quat import (
    Vec3,
    body_z_axis_ned,
    quat_conjugate,
    quat_multiply,
    quat_normalized,
    rotate_ned_to_body,
)


class AttitudeControl:
    """PX4 AttitudeControl: quaternion error with reduced (tilt-first) attitude and yaw weight."""

    def __init__(self) -> None:
        self.read_params_from(None)

    def read_params_from(self, params: ParamReader | None) -> None:
        get = functools.partial(param_or, params)
        self.yaw_weight = clamp(get("MC_YAW_WEIGHT", 0.4), 0.0, 1.0)
        yaw_p = get("MC_YAW_P", 2.8)
        self.gain_p = (
            get("MC_ROLL_P", 6.5),
            get("MC_PITCH_P", 6.5),
            yaw_p / self.yaw_weight if self.yaw_weight > 1e-4 else yaw_p,
        )
        self.rate_limit_rad_s = (
            math.radians(get("MC_ROLLRATE_MAX", 220.0)),
            math.radians(get("MC_PITCHRATE_MAX", 220.0)),
            math.radians(get("MC_YAWRATE_MAX", 200.0)),
        )

    def update(
        self,
        q: list[float],
        q_sp: tuple[float, float, float, float],
        yawspeed_sp_rad_s: float = math.nan,
    ) -> Vec3:
        e_z = body_z_axis_ned(q)
        e_z_d = body_z_axis_ned(q_sp)
        q_red = _quat_between(e_z, e_z_d)
        if abs(q_red[1]) > 1.0 - 1e-5 or abs(q_red[2]) > 1.0 - 1e-5:
            qd_red = q_sp
        else:
            qd_red = quat_multiply(q_red, q)
        q_mix = quat_multiply(quat_conjugate(qd_red), q_sp)
        if q_mix[0] < 0.0:
            q_mix = (-q_mix[0], -q_mix[1], -q_mix[2], -q_mix[3])
        w = clamp(q_mix[0], -1.0, 1.0)
        z = clamp(q_mix[3], -1.0, 1.0)
        yw = self.yaw_weight
        yaw_part = (math.cos(yw * math.acos(w)), 0.0, 0.0, math.sin(yw * math.asin(z)))
        qd = quat_multiply(qd_red, yaw_part)
        qe = quat_multiply(quat_conjugate(q), qd)
        if qe[0] < 0.0:
            qe = (-qe[0], -qe[1], -qe[2], -qe[3])
        gain = self.gain_p
        rates = [2.0 * qe[1] * gain[0], 2.0 * qe[2] * gain[1], 2.0 * qe[3] * gain[2]]
        if is_finite(yawspeed_sp_rad_s):
            ff = rotate_ned_to_body(q, (0.0, 0.0, yawspeed_sp_rad_s))
            rates = [rates[i] + ff[i] for i in range(3)]
        lim = self.rate_limit_rad_s
        return (
            clamp(rates[0], -lim[0], lim[0]),
            clamp(rates[1], -lim[1], lim[1]),
            clamp(rates[2], -lim[2], lim[2]),
        )


def _quat_between(src: Vec3, dst: Vec3) -> tuple[float, float, float, float]:
    """Shortest rotation taking unit vector src to dst (matrix::Quaternion(src, dst))."""
    cx = src[1] * dst[2] - src[2] * dst[1]
    cy = src[2] * dst[0] - src[0] * dst[2]
    cz = src[0] * dst[1] - src[1] * dst[0]
    dt = src[0] * dst[0] + src[1] * dst[1] + src[2] * dst[2]
    if cx * cx + cy * cy + cz * cz < 1e-10 and dt < 0.0:
        # opposite vectors: rotate by pi about any axis perpendicular to src
        if abs(src[0]) < 0.9:
            return quat_normalized((0.0, 0.0, -src[2], src[1]))
        return quat_normalized((0.0, src[2], 0.0, -src[0]))
    w = dt + math.sqrt(dt * dt + cx * cx + cy * cy + cz * cz)
    return quat_normalized((w, cx, cy, cz))
