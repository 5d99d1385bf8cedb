"""Fixed-wing control after PX4's fw_pos_control, TECS and fw_att_control, simplified.

Guidance: a position setpoint means "fly to that point, then circle it" (a vector field that
converges on the loiter circle, clockwise like PX4's positive loiter radius); a velocity
setpoint means "fly that course". Height and speed: a flight-path-angle/energy controller in
the spirit of TECS (pitch sets the climb angle, throttle pays for drag, climb and
acceleration). Attitude: angle errors over FW_R_TC/FW_P_TC give rates, with coordinated-turn
yaw rate; rates: PX4's FF + PI, scaled by airspeed.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from sim.lib.numeric import clamp, finite_or, is_finite
from sim.lib.params import ParamReader
from sim.lib.quat import euler_from_quat, rotate_ned_to_body, wrap_pi
from sim.lib.topics import (
    AttitudeSetpoint,
    ControlSetpoint,
    RatesSetpoint,
    TrajectorySetpoint,
    VehicleStateTruth,
)
from sim.physics.rigid_body import GRAVITY_M_S2

# How hard the course converges onto the loiter circle, and onto the commanded course
ORBIT_CONVERGENCE = 2.0
COURSE_P_PER_S = 0.8
# Height error to climb rate (1/FW_T_ALT_TC-like) and climb-rate PI onto pitch
HEIGHT_P_PER_S = 0.4
CLIMB_RATE_P_RAD_S_M = 0.06
CLIMB_RATE_I_RAD_M = 0.03
SPEED_P_PER_S = 0.6
SPEED_I_THROTTLE_PER_M = 0.04
STALL_PITCH_LIMIT_RAD = math.radians(10.0)
# Runway takeoff: the nose comes up to this pitch once the airspeed reaches FW_AIRSPD_MIN
# (PX4's runway takeoff rotates and climbs at FW_TKO_PITCH_MIN, 10°)
ROTATION_PITCH_RAD = math.radians(10.0)


class SurfacesThrottle(NamedTuple):
    """Normalised outputs: aileron/elevator/rudder in [-1, 1], throttle in [0, 1]."""

    aileron: float = 0.0
    elevator: float = 0.0
    rudder: float = 0.0
    throttle: float = 0.0


class FixedWingControl:
    """Guidance, height/speed and attitude/rate control of a fixed wing (plane or VTOL in FW)."""

    def __init__(self, params: ParamReader, mass_kg: float, thrust_max_n: float) -> None:
        self.params = params
        self.mass_kg = mass_kg
        self.thrust_max_n = thrust_max_n
        self.rate_int = [0.0, 0.0, 0.0]
        self.climb_int_rad = 0.0
        self.speed_int = 0.0
        self.hold_down_m = math.nan
        self.hold_course_rad = math.nan
        self.refresh_params()

    def refresh_params(self) -> None:
        g = self.params.get
        self.airspeed_min_m_s = g("FW_AIRSPD_MIN")
        self.airspeed_trim_m_s = g("FW_AIRSPD_TRIM")
        self.airspeed_max_m_s = g("FW_AIRSPD_MAX")
        self.loiter_radius_m = g("NAV_LOITER_RAD")
        self.roll_limit_rad = math.radians(g("FW_R_LIM"))
        self.pitch_max_rad = math.radians(g("FW_P_LIM_MAX"))
        self.pitch_min_rad = math.radians(g("FW_P_LIM_MIN"))
        self.roll_tc_s = max(g("FW_R_TC"), 0.05)
        self.pitch_tc_s = max(g("FW_P_TC"), 0.05)
        self.climb_max_m_s = g("FW_T_CLMB_MAX")
        self.sink_max_m_s = g("FW_T_SINK_MAX")
        self.thr_trim = g("FW_THR_TRIM")
        self.thr_max = g("FW_THR_MAX")
        self.thr_min = g("FW_THR_MIN")
        self.thr_idle = g("FW_THR_IDLE")
        self.flare_height_m = g("FW_LND_FLALT")
        self.flare_pitch_rad = math.radians(g("FW_LND_FL_PMIN"))
        self.rate_p = (g("FW_RR_P"), g("FW_PR_P"), g("FW_YR_P"))
        self.rate_i = (g("FW_RR_I"), g("FW_PR_I"), g("FW_YR_I"))
        self.rate_ff = (g("FW_RR_FF"), g("FW_PR_FF"), g("FW_YR_FF"))
        self.rate_max_rad_s = (
            math.radians(g("FW_R_RMAX")),
            math.radians(g("FW_P_RMAX_POS")),
            math.radians(g("FW_Y_RMAX")),
        )

    def reset(self) -> None:
        self.rate_int = [0.0, 0.0, 0.0]
        self.climb_int_rad = 0.0
        self.speed_int = 0.0
        self.hold_down_m = math.nan
        self.hold_course_rad = math.nan

    def update(
        self, dt_s: float, truth: VehicleStateTruth, setpoint: ControlSetpoint
    ) -> SurfacesThrottle:
        roll, pitch, yaw = euler_from_quat(truth.q_wxyz)
        if isinstance(setpoint, RatesSetpoint):
            surfaces = self.rate_control(dt_s, truth, setpoint.rates_rad_s)
            return surfaces._replace(throttle=clamp(setpoint.thrust_body[0], 0.0, 1.0))
        if isinstance(setpoint, AttitudeSetpoint):
            roll_sp, pitch_sp, _ = euler_from_quat(setpoint.q_wxyz)
            throttle = setpoint.thrust_body[0]
        else:
            roll_sp, pitch_sp, throttle = self._guidance(dt_s, truth, setpoint, yaw)
        rates_sp = self.attitude_rates(truth, roll, pitch, roll_sp, pitch_sp)
        surfaces = self.rate_control(dt_s, truth, rates_sp)
        return surfaces._replace(throttle=clamp(throttle, 0.0, 1.0))

    # -- guidance ------------------------------------------------------------------------

    def _guidance(
        self, dt_s: float, truth: VehicleStateTruth, sp: TrajectorySetpoint, yaw: float
    ) -> tuple[float, float, float]:
        """Roll and pitch setpoints and throttle for a trajectory setpoint."""
        airspeed = max(truth.airspeed_m_s, 1.0)
        roll_sp, speed_sp = self._lateral(truth, sp, yaw, airspeed)
        climb_sp = self._climb_rate_setpoint(truth, sp)
        if truth.on_ground:
            # runway takeoff: wings level, full throttle while the target is above us, the
            # nose up once fast enough to fly
            self.climb_int_rad = 0.0
            self.speed_int = 0.0
            if climb_sp <= 0.5:
                return 0.0, 0.0, 0.0
            rotate = truth.airspeed_m_s >= self.airspeed_min_m_s
            return 0.0, ROTATION_PITCH_RAD if rotate else 0.0, self.thr_max
        if climb_sp < 0.0 and -truth.position_ned_m[2] < self.flare_height_m:
            # landing flare (PX4 below FW_LND_FLALT): wings level, nose at FW_LND_FL_PMIN,
            # throttle idle, so the wheels stay down once they touch
            self.climb_int_rad = 0.0
            self.speed_int = 0.0
            return 0.0, self.flare_pitch_rad, self.thr_idle
        pitch_sp, throttle = self._longitudinal(dt_s, truth, climb_sp, speed_sp, airspeed)
        return roll_sp, pitch_sp, throttle

    def _lateral(
        self, truth: VehicleStateTruth, sp: TrajectorySetpoint, yaw: float, airspeed: float
    ) -> tuple[float, float]:
        """Roll setpoint towards the commanded course or loiter circle, and the speed to fly."""
        pos, vel = truth.position_ned_m, truth.velocity_ned_m_s
        course = math.atan2(vel[1], vel[0]) if math.hypot(vel[0], vel[1]) > 1.0 else yaw
        target, sp_vel = sp.position_ned_m, sp.velocity_ned_m_s
        speed_sp = self.airspeed_trim_m_s
        if is_finite(sp.max_speed_xy_m_s) and sp.max_speed_xy_m_s > 0.0:
            speed_sp = sp.max_speed_xy_m_s
        accel_ff = 0.0
        commanded_speed = math.hypot(sp_vel[0], sp_vel[1])
        if is_finite(target[0]) and is_finite(target[1]):
            radius = sp.loiter_radius_m if is_finite(sp.loiter_radius_m) else self.loiter_radius_m
            course_sp, accel_ff = _orbit_course(
                pos[0] - target[0], pos[1] - target[1], max(abs(radius), 1.0), airspeed
            )
            self.hold_course_rad = math.nan
        elif is_finite(commanded_speed) and commanded_speed > 0.1:
            course_sp = math.atan2(sp_vel[1], sp_vel[0])
            speed_sp = commanded_speed
            self.hold_course_rad = math.nan
        else:
            if not is_finite(self.hold_course_rad):
                self.hold_course_rad = course
            course_sp = self.hold_course_rad
        lateral_accel = COURSE_P_PER_S * airspeed * wrap_pi(course_sp - course) + accel_ff
        roll_sp = clamp(
            math.atan2(lateral_accel, GRAVITY_M_S2), -self.roll_limit_rad, self.roll_limit_rad
        )
        return roll_sp, clamp(speed_sp, self.airspeed_min_m_s, self.airspeed_max_m_s)

    def _climb_rate_setpoint(self, truth: VehicleStateTruth, sp: TrajectorySetpoint) -> float:
        """Climb rate (m/s, up) towards the setpoint's altitude, its vertical speed, or the
        altitude held when it has neither; within FW_T_CLMB_MAX / FW_T_SINK_MAX and the
        setpoint's own vertical speed limits (a landing circles down at the land speed)."""
        down = truth.position_ned_m[2]
        if is_finite(sp.position_ned_m[2]):
            self.hold_down_m = math.nan
            climb_sp = -HEIGHT_P_PER_S * (sp.position_ned_m[2] - down)
        elif is_finite(sp.velocity_ned_m_s[2]):
            self.hold_down_m = math.nan
            climb_sp = -sp.velocity_ned_m_s[2]
        else:
            if not is_finite(self.hold_down_m):
                self.hold_down_m = down
            climb_sp = -HEIGHT_P_PER_S * (self.hold_down_m - down)
        sink_max = min(self.sink_max_m_s, finite_or(sp.max_speed_down_m_s, math.inf))
        climb_max = min(self.climb_max_m_s, finite_or(sp.max_speed_up_m_s, math.inf))
        return clamp(climb_sp, -sink_max, climb_max)

    def _longitudinal(
        self,
        dt_s: float,
        truth: VehicleStateTruth,
        climb_sp: float,
        speed_sp: float,
        airspeed: float,
    ) -> tuple[float, float]:
        """Pitch for the climb angle (plus the angle of attack the wing flies at), throttle
        for drag, climb and acceleration: the TECS split of duties."""
        gamma_sp = math.asin(clamp(climb_sp / airspeed, -0.5, 0.5))
        # a turn needs more lift than level flight: the integrator supplies it
        climb_error = climb_sp + truth.velocity_ned_m_s[2]
        self.climb_int_rad = clamp(
            self.climb_int_rad + CLIMB_RATE_I_RAD_M * climb_error * dt_s, -0.3, 0.3
        )
        alpha = math.atan2(_body_w(truth), airspeed)
        pitch_sp = gamma_sp + alpha + CLIMB_RATE_P_RAD_S_M * climb_error + self.climb_int_rad
        slow = airspeed < self.airspeed_min_m_s
        if slow:
            # too slow: trade height for speed rather than stall
            pitch_sp = min(pitch_sp, STALL_PITCH_LIMIT_RAD * airspeed / self.airspeed_min_m_s)
        pitch_sp = clamp(pitch_sp, self.pitch_min_rad, self.pitch_max_rad)

        speed_error = speed_sp - airspeed
        self.speed_int = clamp(
            self.speed_int + SPEED_I_THROTTLE_PER_M * speed_error * dt_s, -0.5, 1.0
        )
        accel_needed = SPEED_P_PER_S * speed_error + GRAVITY_M_S2 * math.sin(gamma_sp)
        # FW_THR_TRIM holds trim speed in level flight; the integrator learns the rest
        throttle = (
            self.thr_trim + self.speed_int + accel_needed * self.mass_kg / self.thrust_max_n
        )
        if slow:
            throttle = self.thr_max
        return pitch_sp, clamp(throttle, self.thr_min, self.thr_max)

    # -- attitude and rates --------------------------------------------------------------

    def attitude_rates(
        self,
        truth: VehicleStateTruth,
        roll: float,
        pitch: float,
        roll_sp: float,
        pitch_sp: float,
    ) -> tuple[float, float, float]:
        """Body rate setpoints: angle errors over time constants plus the coordinated turn."""
        roll_dot = (roll_sp - roll) / self.roll_tc_s
        pitch_dot = (pitch_sp - pitch) / self.pitch_tc_s
        speed = max(truth.airspeed_m_s, self.airspeed_min_m_s)
        yaw_dot = GRAVITY_M_S2 * math.tan(clamp(roll, -1.2, 1.2)) / speed
        sr, cr = math.sin(roll), math.cos(roll)
        sp, cp = math.sin(pitch), math.cos(pitch)
        p = roll_dot - yaw_dot * sp
        q = pitch_dot * cr + yaw_dot * sr * cp
        r = -pitch_dot * sr + yaw_dot * cr * cp
        lim = self.rate_max_rad_s
        return (clamp(p, -lim[0], lim[0]), clamp(q, -lim[1], lim[1]), clamp(r, -lim[2], lim[2]))

    def rate_control(
        self, dt_s: float, truth: VehicleStateTruth, rates_sp: tuple[float, float, float]
    ) -> SurfacesThrottle:
        # control surfaces bite with dynamic pressure: scale outputs by trim/actual airspeed
        speed = max(truth.airspeed_m_s, 0.5 * self.airspeed_min_m_s)
        scaler = clamp(self.airspeed_trim_m_s / speed, 0.3, 2.0)
        out = [0.0, 0.0, 0.0]
        rates = truth.rates_body_rad_s
        for i in range(3):
            err = rates_sp[i] - rates[i]
            if not truth.on_ground:
                self.rate_int[i] = clamp(
                    self.rate_int[i] + self.rate_i[i] * err * dt_s * scaler, -0.4, 0.4
                )
            raw = (self.rate_ff[i] * rates_sp[i] + self.rate_p[i] * err) * scaler + self.rate_int[i]
            out[i] = clamp(raw, -1.0, 1.0)
        return SurfacesThrottle(aileron=out[0], elevator=out[1], rudder=out[2])


def _body_w(truth: VehicleStateTruth) -> float:
    """Body-down component of the velocity (for the angle of attack)."""
    return rotate_ned_to_body(truth.q_wxyz, truth.velocity_ned_m_s)[2]


def _orbit_course(
    north_m: float, east_m: float, radius_m: float, airspeed_m_s: float
) -> tuple[float, float]:
    """Course onto a clockwise circle around the origin, and the centripetal acceleration
    the circle needs once on it (Beard & McLain's orbit vector field)."""
    distance = math.hypot(north_m, east_m)
    bearing_from_centre = math.atan2(east_m, north_m)
    course = bearing_from_centre + math.pi / 2.0 + math.atan(
        ORBIT_CONVERGENCE * (distance - radius_m) / radius_m
    )
    on_circle = max(0.0, 1.0 - abs(distance - radius_m) / radius_m)
    accel = on_circle * airspeed_m_s * airspeed_m_s / radius_m
    return wrap_pi(course), accel
