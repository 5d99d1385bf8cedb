"""Multicopter position and velocity control after PX4's mc_pos_control (PositionControl).

position P → velocity PID (+ feed-forward) → acceleration → body z + collective thrust,
with hover thrust producing standard gravity. It runs at 50 Hz like PX4's position
controller (POSITION_LOOP_PERIOD_S); `sim.control.mc_att_control` takes its attitude setpoint.
"""

from __future__ import annotations

import functools
import math

from sim.lib.numeric import clamp, finite_or, is_finite
from sim.lib.params import ParamReader, param_or
from sim.lib.quat import quat_from_body_z_and_yaw, wrap_pi, yaw_from_quat
from sim.lib.topics import TrajectorySetpoint, VehicleStateTruth
from sim.physics.rigid_body import GRAVITY_M_S2

POSITION_LOOP_PERIOD_S = 0.02


class PositionControl:
    """PX4 PositionControl: trajectory setpoint → attitude quaternion + collective thrust."""

    def __init__(self) -> None:
        self.vel_int = [0.0, 0.0, 0.0]
        self.yaw_sp_rad = math.nan
        self.yawspeed_sp_rad_s = math.nan
        self.hold_position_ned_m: list[float] | None = None
        self.hover_thrust = 0.5
        # the vertical velocity setpoint of the last update (NaN: not controlled)
        self.vel_sp_down_m_s = math.nan
        self.read_params_from(None)

    def read_params_from(self, params: ParamReader | None) -> None:
        get = functools.partial(param_or, params)
        self.gain_pos_p = (get("MPC_XY_P", 0.95),) * 2 + (get("MPC_Z_P", 1.0),)
        xy_p, z_p = get("MPC_XY_VEL_P_ACC", 1.8), get("MPC_Z_VEL_P_ACC", 4.0)
        xy_i, z_i = get("MPC_XY_VEL_I_ACC", 0.4), get("MPC_Z_VEL_I_ACC", 2.0)
        xy_d, z_d = get("MPC_XY_VEL_D_ACC", 0.2), get("MPC_Z_VEL_D_ACC", 0.0)
        self.gain_vel_p = (xy_p, xy_p, z_p)
        self.gain_vel_i = (xy_i, xy_i, z_i)
        self.gain_vel_d = (xy_d, xy_d, z_d)
        self.vel_max_xy_m_s = get("MPC_XY_VEL_MAX", 12.0)
        self.vel_max_up_m_s = get("MPC_Z_VEL_MAX_UP", 3.0)
        self.vel_max_down_m_s = get("MPC_Z_VEL_MAX_DN", 1.5)
        self.tilt_max_rad = math.radians(get("MPC_TILTMAX_AIR", 45.0))
        self.thr_min = get("MPC_THR_MIN", 0.08)
        self.thr_max = get("MPC_THR_MAX", 1.0)
        self.thr_xy_margin = get("MPC_THR_XY_MARG", 0.3)

    def reset(self) -> None:
        self.vel_int = [0.0, 0.0, 0.0]
        self.yaw_sp_rad = math.nan
        self.hold_position_ned_m = None

    def update(
        self, dt_s: float, truth: VehicleStateTruth, sp: TrajectorySetpoint, landed: bool
    ) -> tuple[tuple[float, float, float, float], float]:
        """Attitude setpoint (w, x, y, z) and collective thrust in [0, 1]."""
        given = (*sp.position_ned_m, *sp.velocity_ned_m_s, *sp.acceleration_ned_m_s2)
        if not any(is_finite(v) for v in given):
            # nothing controllable: PX4's failsafe would hold, so hold where it is now
            if self.hold_position_ned_m is None:
                self.hold_position_ned_m = list(truth.position_ned_m)
            pos_sp = self.hold_position_ned_m
        else:
            self.hold_position_ned_m = None
            pos_sp = sp.position_ned_m
        self._update_yaw_setpoint(dt_s, truth, sp)
        vel_sp = self._velocity_setpoint(truth, sp, pos_sp)
        self.vel_sp_down_m_s = vel_sp[2]
        thr_sp = self._velocity_control(dt_s, truth, vel_sp, sp.acceleration_ned_m_s2, landed)
        collective = math.sqrt(thr_sp[0] ** 2 + thr_sp[1] ** 2 + thr_sp[2] ** 2)
        if collective > 1e-6:
            body_z = (-thr_sp[0] / collective, -thr_sp[1] / collective, -thr_sp[2] / collective)
        else:
            body_z = (0.0, 0.0, 1.0)
        return quat_from_body_z_and_yaw(body_z, self.yaw_sp_rad), collective

    def _velocity_setpoint(
        self, truth: VehicleStateTruth, sp: TrajectorySetpoint, pos_sp: list[float]
    ) -> list[float]:
        """Position P plus velocity feed-forward, limited; NaN where neither is given."""
        pos = truth.position_ned_m
        vel_ff = sp.velocity_ned_m_s
        lim_xy = finite_or(sp.max_speed_xy_m_s, self.vel_max_xy_m_s)
        lim_up = finite_or(sp.max_speed_up_m_s, self.vel_max_up_m_s)
        lim_dn = finite_or(sp.max_speed_down_m_s, self.vel_max_down_m_s)
        vel_from_pos = [
            (pos_sp[i] - pos[i]) * self.gain_pos_p[i] if is_finite(pos_sp[i]) else math.nan
            for i in range(3)
        ]
        vel_sp = [_add_if_finite(vel_ff[i], vel_from_pos[i]) for i in range(3)]
        # horizontally the way to the target has priority over the feed-forward
        vel_sp_xy = _constrain_xy(
            [finite_or(v, 0.0) for v in vel_from_pos[:2]],
            [finite_or(v, 0.0) for v in vel_ff[:2]],
            lim_xy,
        )
        for i in range(2):
            if is_finite(vel_sp[i]):
                vel_sp[i] = vel_sp_xy[i]
        if is_finite(vel_sp[2]):
            vel_sp[2] = clamp(vel_sp[2], -lim_up, lim_dn)
        return vel_sp

    def _velocity_control(
        self,
        dt_s: float,
        truth: VehicleStateTruth,
        vel_sp: list[float],
        acc_ff: list[float],
        landed: bool,
    ) -> list[float]:
        """Velocity PID plus acceleration feed-forward → thrust vector (NED, normalised)."""
        vel = truth.velocity_ned_m_s
        acc = truth.acceleration_ned_m_s2
        vel_error = [vel_sp[i] - vel[i] for i in range(3)]
        acc_sp = [finite_or(a, 0.0) for a in acc_ff]
        any_acc = any(is_finite(a) for a in acc_ff)
        for i in range(3):
            if is_finite(vel_error[i]):
                p_term = vel_error[i] * self.gain_vel_p[i]
                acc_sp[i] += p_term + self.vel_int[i] - acc[i] * self.gain_vel_d[i]
            elif not any_acc:
                # axis uncontrolled: damp it so the vehicle does not drift away
                acc_sp[i] -= vel[i] * self.gain_vel_p[i]
        thr_sp = self._acceleration_to_thrust(acc_sp)

        # anti-windup: vertical stops integrating when thrust saturates that way
        ez = vel_error[2]
        if is_finite(ez) and (
            (thr_sp[2] >= -self.thr_min and ez >= 0.0) or (thr_sp[2] <= -self.thr_max and ez <= 0.0)
        ):
            vel_error[2] = 0.0
        thr_sp = self._limit_thrust_keeping_vertical(thr_sp)
        # horizontally, tracking anti-windup (Rundqwist): integrate only what was produced
        scale = GRAVITY_M_S2 / self.hover_thrust
        produced = (thr_sp[0] * scale, thr_sp[1] * scale)
        wanted = (acc_sp[0], acc_sp[1])
        too_much = wanted[0] ** 2 + wanted[1] ** 2 > produced[0] ** 2 + produced[1] ** 2
        limited = produced if too_much else wanted
        arw_gain = 2.0 / self.gain_vel_p[0] if self.gain_vel_p[0] > 0 else 0.0
        for i in range(2):
            vel_error[i] -= arw_gain * (wanted[i] - limited[i])
        if not landed:
            for i in range(3):
                if is_finite(vel_error[i]):
                    self.vel_int[i] += vel_error[i] * self.gain_vel_i[i] * dt_s
            self.vel_int[2] = clamp(self.vel_int[2], -GRAVITY_M_S2, GRAVITY_M_S2)
        return thr_sp

    def _update_yaw_setpoint(
        self, dt_s: float, truth: VehicleStateTruth, sp: TrajectorySetpoint
    ) -> None:
        yaw_now = yaw_from_quat(truth.q_wxyz)
        if is_finite(sp.yaw_rad):
            self.yaw_sp_rad = wrap_pi(sp.yaw_rad)
        elif is_finite(sp.yawspeed_rad_s):
            start = self.yaw_sp_rad if is_finite(self.yaw_sp_rad) else yaw_now
            # keep the integrated setpoint near the vehicle so it cannot run away
            if abs(wrap_pi(start - yaw_now)) > 0.5:
                start = yaw_now
            self.yaw_sp_rad = wrap_pi(start + sp.yawspeed_rad_s * dt_s)
        elif not is_finite(self.yaw_sp_rad):
            self.yaw_sp_rad = yaw_now
        self.yawspeed_sp_rad_s = sp.yawspeed_rad_s

    def _acceleration_to_thrust(self, acc_sp: list[float]) -> list[float]:
        """PX4 _accelerationControl: tilt from the horizontal acceleration, thrust from the
        vertical one, with hover thrust producing standard gravity."""
        z_specific_force = -GRAVITY_M_S2 + acc_sp[2]
        bz = [-acc_sp[0], -acc_sp[1], -z_specific_force]
        norm = math.sqrt(bz[0] ** 2 + bz[1] ** 2 + bz[2] ** 2)
        bz = [0.0, 0.0, 1.0] if norm < 1e-6 else [bz[0] / norm, bz[1] / norm, bz[2] / norm]
        bz = _limit_tilt(bz, self.tilt_max_rad)
        thrust_ned_z = acc_sp[2] * (self.hover_thrust / GRAVITY_M_S2) - self.hover_thrust
        cos_ned_body = bz[2]
        collective = min(thrust_ned_z / cos_ned_body, -self.thr_min) if cos_ned_body > 1e-3 else (
            -self.thr_min
        )
        return [bz[0] * collective, bz[1] * collective, bz[2] * collective]

    def _limit_thrust_keeping_vertical(self, thr: list[float]) -> list[float]:
        """Vertical thrust first, keeping MPC_THR_XY_MARG for horizontal control."""
        xy_norm = math.sqrt(thr[0] ** 2 + thr[1] ** 2)
        thr_max_sq = self.thr_max**2
        allocated_xy = min(xy_norm, self.thr_xy_margin)
        z = max(thr[2], -math.sqrt(max(thr_max_sq - allocated_xy**2, 0.0)))
        xy_max_sq = thr_max_sq - z * z
        xy_max = math.sqrt(xy_max_sq) if xy_max_sq > 0.0 else 0.0
        x, y = thr[0], thr[1]
        if xy_norm > xy_max and xy_norm > 0.0:
            x, y = x / xy_norm * xy_max, y / xy_norm * xy_max
        return [x, y, z]


def _add_if_finite(base: float, addition: float) -> float:
    if not is_finite(addition):
        return base
    if not is_finite(base):
        return addition
    return base + addition


def _constrain_xy(v0: list[float], v1: list[float], max_norm: float) -> list[float]:
    """PX4 ControlMath::constrainXY: keep v0 (towards the target) first, then as much of the
    feed-forward v1 as fits inside max_norm."""
    v1 = [x if is_finite(x) else 0.0 for x in v1]
    sx, sy = v0[0] + v1[0], v0[1] + v1[1]
    if math.hypot(sx, sy) <= max_norm:
        return [sx, sy]
    n0 = math.hypot(v0[0], v0[1])
    if n0 >= max_norm:
        return [v0[0] / n0 * max_norm, v0[1] / n0 * max_norm]
    if abs(math.hypot(v1[0], v1[1])) < 1e-6:
        return [v0[0], v0[1]]
    # largest s with |v0 + s·v1| = max_norm
    a = v1[0] ** 2 + v1[1] ** 2
    b = 2.0 * (v0[0] * v1[0] + v0[1] * v1[1])
    c = n0 * n0 - max_norm * max_norm
    s = (-b + math.sqrt(max(b * b - 4.0 * a * c, 0.0))) / (2.0 * a)
    return [v0[0] + s * v1[0], v0[1] + s * v1[1]]


def _limit_tilt(bz: list[float], tilt_max_rad: float) -> list[float]:
    """PX4 ControlMath::limitTilt against the vertical."""
    cos_tilt = clamp(bz[2], -1.0, 1.0)
    angle = math.acos(cos_tilt)
    if angle <= tilt_max_rad:
        return bz
    horiz = math.hypot(bz[0], bz[1])
    if horiz < 1e-9:
        return [0.0, 0.0, 1.0]
    s = math.sin(tilt_max_rad) / horiz
    return [bz[0] * s, bz[1] * s, math.cos(tilt_max_rad)]
