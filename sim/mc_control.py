"""Multicopter cascade after PX4's mc_pos_control, mc_att_control and mc_rate_control.

position P → velocity PID (+ feed-forward) → acceleration → body z + collective thrust
(hover thrust from mass and SIH_T_MAX) → attitude P (roll/pitch prioritised over yaw) →
rate PID → normalised torque for the mixer. The position/velocity part runs at 50 Hz like
PX4's position controller; attitude and rates run at every physics step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim.numeric import clamp, finite_or, is_finite
from sim.params import ParamReader
from sim.quat import (
    Vec3,
    body_z_axis_ned,
    quat_conjugate,
    quat_from_body_z_and_yaw,
    quat_multiply,
    quat_normalized,
    rotate_ned_to_body,
    wrap_pi,
    yaw_from_quat,
)
from sim.rigid_body import GRAVITY_M_S2
from sim.topics import (
    AttitudeSetpoint,
    ControlSetpoint,
    RatesSetpoint,
    TrajectorySetpoint,
    VehicleStateTruth,
)

POSITION_LOOP_PERIOD_S = 0.02


@dataclass
class TorqueThrust:
    """Normalised commands for the mixer: roll/pitch/yaw in [-1, 1], thrust in [0, 1]."""

    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    thrust: float = 0.0


class PositionControl:
    """PX4 PositionControl: trajectory setpoint → attitude quaternion + collective thrust."""

    def __init__(self) -> None:
        self.vel_int = [0.0, 0.0, 0.0]
        self.yaw_sp_rad = math.nan
        self.yawspeed_sp_rad_s = math.nan
        self.hold_position_ned_m: list[float] | None = None
        self.hover_thrust = 0.5
        self.read_params_from(None)

    def read_params_from(self, params: ParamReader | None) -> None:
        def get(name: str, default: float) -> float:
            return default if params is None else float(params.get(name))

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


class AttitudeControl:
    """PX4 AttitudeControl: quaternion error with reduced (tilt-first) attitude and yaw weight."""

    def __init__(self) -> None:
        self.read_params_from(None)

    def read_params_from(self, params: ParamReader | None) -> None:
        def get(name: str, default: float) -> float:
            return default if params is None else float(params.get(name))

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


class RateControl:
    """PX4 RateControl: PID on body rates with integrator limits, frozen while landed."""

    def __init__(self) -> None:
        self.rate_int = [0.0, 0.0, 0.0]
        self._prev_rates: Vec3 | None = None
        self.read_params_from(None)

    def read_params_from(self, params: ParamReader | None) -> None:
        def get(name: str, default: float) -> float:
            return default if params is None else float(params.get(name))

        k = (get("MC_ROLLRATE_K", 1.0), get("MC_PITCHRATE_K", 1.0), get("MC_YAWRATE_K", 1.0))
        self.gain_p = (
            k[0] * get("MC_ROLLRATE_P", 0.15),
            k[1] * get("MC_PITCHRATE_P", 0.15),
            k[2] * get("MC_YAWRATE_P", 0.2),
        )
        self.gain_i = (
            k[0] * get("MC_ROLLRATE_I", 0.2),
            k[1] * get("MC_PITCHRATE_I", 0.2),
            k[2] * get("MC_YAWRATE_I", 0.1),
        )
        self.gain_d = (
            k[0] * get("MC_ROLLRATE_D", 0.003),
            k[1] * get("MC_PITCHRATE_D", 0.003),
            k[2] * get("MC_YAWRATE_D", 0.0),
        )
        self.int_lim = (
            get("MC_RR_INT_LIM", 0.3),
            get("MC_PR_INT_LIM", 0.3),
            get("MC_YR_INT_LIM", 0.3),
        )

    def reset(self) -> None:
        self.rate_int = [0.0, 0.0, 0.0]
        self._prev_rates = None

    def update(
        self, dt_s: float, rates: list[float], rates_sp: Vec3, landed: bool, saturated: bool
    ) -> Vec3:
        prev = self._prev_rates
        current = (rates[0], rates[1], rates[2])
        self._prev_rates = current
        out = [0.0, 0.0, 0.0]
        for i in range(3):
            err = rates_sp[i] - current[i]
            accel = 0.0 if prev is None else (current[i] - prev[i]) / dt_s
            out[i] = self.gain_p[i] * err + self.rate_int[i] - self.gain_d[i] * accel
            if not landed and not saturated:
                # PX4 shrinks the integration for large errors to avoid windup on flips
                i_factor = max(0.0, 1.0 - (err / math.radians(400.0)) ** 2)
                lim = self.int_lim[i]
                self.rate_int[i] = clamp(
                    self.rate_int[i] + i_factor * self.gain_i[i] * err * dt_s, -lim, lim
                )
        return (out[0], out[1], out[2])


class MulticopterControl:
    """The whole cascade; `update` returns the mixer input for one physics step."""

    def __init__(self, params: ParamReader) -> None:
        self.params = params
        self.position = PositionControl()
        self.attitude = AttitudeControl()
        self.rates = RateControl()
        self._since_position_s = math.inf
        self._since_params_s = math.inf
        self._q_sp: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
        self._thrust = 0.0
        self.mixer_saturated = False
        self.refresh_params()

    def refresh_params(self) -> None:
        self.position.read_params_from(self.params)
        self.attitude.read_params_from(self.params)
        self.rates.read_params_from(self.params)
        self._since_params_s = 0.0

    def reset(self) -> None:
        self.position.reset()
        self.rates.reset()
        self._since_position_s = math.inf

    def update(
        self,
        dt_s: float,
        truth: VehicleStateTruth,
        setpoint: ControlSetpoint,
        hover_thrust: float,
    ) -> TorqueThrust:
        # parameters take effect within 0.2 s without a lookup at every step
        self._since_params_s += dt_s
        if self._since_params_s >= 0.2:
            self.refresh_params()
        landed = truth.on_ground
        q = truth.q_wxyz
        if isinstance(setpoint, RatesSetpoint):
            rates_sp = setpoint.rates_rad_s
            thrust = -setpoint.thrust_body[2]
            self._since_position_s = math.inf
        else:
            if isinstance(setpoint, AttitudeSetpoint):
                self._q_sp = setpoint.q_wxyz
                self._thrust = -setpoint.thrust_body[2]
                self._since_position_s = math.inf
                yawspeed = math.nan
                self.position.yaw_sp_rad = math.nan
            else:
                self._since_position_s += dt_s
                if self._since_position_s >= POSITION_LOOP_PERIOD_S - 1e-9:
                    # after a pause (other setpoint types, reset) integrate one period only
                    period = min(self._since_position_s, POSITION_LOOP_PERIOD_S)
                    self.position.hover_thrust = hover_thrust
                    self._q_sp, self._thrust = self.position.update(
                        period, truth, setpoint, landed
                    )
                    self._since_position_s = 0.0
                yawspeed = self.position.yawspeed_sp_rad_s
            rates_sp = self.attitude.update(q, self._q_sp, yawspeed)
            thrust = self._thrust
        torque = self.rates.update(
            dt_s, truth.rates_body_rad_s, rates_sp, landed, self.mixer_saturated
        )
        return TorqueThrust(torque[0], torque[1], torque[2], clamp(thrust, 0.0, 1.0))
