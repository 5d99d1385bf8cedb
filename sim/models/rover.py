"""Differential-drive rover: unicycle kinematics with acceleration and yaw-rate limits.

Position setpoint: turn towards it (in place when it is behind), drive at GND_SPEED_TRIM (or
the setpoint's speed limit), slow down to arrive, stop within ARRIVAL_RADIUS_M and then turn
to the setpoint's yaw if it has one. Velocity setpoint: hold that course and speed, at most
GND_SPEED_MAX. Outputs: left and right wheel speeds, normalised to [-1, 1] (reversible).
"""

from __future__ import annotations

import math

from sim.control.setpoint_guard import safe_setpoint
from sim.lib.numeric import clamp, is_finite
from sim.lib.params import ParamReader
from sim.lib.quat import quat_from_yaw, wrap_pi, yaw_from_quat
from sim.lib.topics import (
    AttitudeSetpoint,
    ControlSetpoint,
    LandingStatus,
    RatesSetpoint,
    TrajectorySetpoint,
    VehicleStateTruth,
    VtolState,
)
from sim.models.multicopter import PARAM_REFRESH_PERIOD_S

MAV_TYPE_GROUND_ROVER = 10
ARRIVAL_RADIUS_M = 0.3
HEADING_P_PER_S = 2.5
YAW_RATE_TAU_S = 0.1


class RoverModel:
    name = "rover"
    mav_type = MAV_TYPE_GROUND_ROVER
    is_vtol = False
    in_fixed_wing_flight = False
    vtol_state = VtolState.UNDEFINED

    def __init__(self, params: ParamReader) -> None:
        self.params = params
        self.truth = VehicleStateTruth()
        self.speed_m_s = 0.0
        self.yaw_rate_rad_s = 0.0
        self.actuator_outputs = [0.0, 0.0]
        self.power_fraction = 0.0
        self.landing: LandingStatus | None = None  # no multicopter land detection
        self._since_refresh_s = math.inf
        self._refresh_params()

    def _refresh_params(self) -> None:
        g = self.params.get
        self.speed_max_m_s = max(g("GND_SPEED_MAX"), 0.1)
        self.speed_trim_m_s = max(g("GND_SPEED_TRIM"), 0.1)
        self.accel_m_s2 = max(g("RO_ACCEL_LIM"), 0.1)
        self.decel_m_s2 = max(g("RO_DECEL_LIM"), 0.1)
        self.yaw_rate_max_rad_s = math.radians(max(g("RO_YAW_RATE_LIM"), 1.0))
        self.wheel_track_m = max(g("RD_WHEEL_TRACK"), 0.05)
        self._since_refresh_s = 0.0

    def step(self, dt_s: float, armed: bool, setpoint: ControlSetpoint | None) -> None:
        self._since_refresh_s += dt_s
        if self._since_refresh_s >= PARAM_REFRESH_PERIOD_S:
            self._refresh_params()
        yaw = yaw_from_quat(self.truth.q_wxyz)
        if armed and setpoint is not None:
            speed_sp, yaw_rate_sp = self._control(safe_setpoint(setpoint, self.truth), yaw)
        else:
            speed_sp, yaw_rate_sp = 0.0, 0.0
        speed_sp = clamp(speed_sp, -self.speed_max_m_s, self.speed_max_m_s)
        yaw_rate_sp = clamp(yaw_rate_sp, -self.yaw_rate_max_rad_s, self.yaw_rate_max_rad_s)

        previous_speed = self.speed_m_s
        limit = (self.accel_m_s2 if abs(speed_sp) > abs(previous_speed) else self.decel_m_s2) * dt_s
        self.speed_m_s += clamp(speed_sp - previous_speed, -limit, limit)
        self.yaw_rate_rad_s += (yaw_rate_sp - self.yaw_rate_rad_s) * min(1.0, dt_s / YAW_RATE_TAU_S)
        self._integrate(dt_s, yaw, previous_speed)

        half_track = 0.5 * self.wheel_track_m
        left = (self.speed_m_s - self.yaw_rate_rad_s * half_track) / self.speed_max_m_s
        right = (self.speed_m_s + self.yaw_rate_rad_s * half_track) / self.speed_max_m_s
        self.actuator_outputs = [clamp(left, -1.0, 1.0), clamp(right, -1.0, 1.0)]
        self.power_fraction = min(1.0, 0.5 * (abs(left) + abs(right)))

    def _integrate(self, dt_s: float, yaw: float, previous_speed: float) -> None:
        t = self.truth
        new_yaw = wrap_pi(yaw + self.yaw_rate_rad_s * dt_s)
        c, s = math.cos(new_yaw), math.sin(new_yaw)
        v = self.speed_m_s
        t.position_ned_m[0] += v * c * dt_s
        t.position_ned_m[1] += v * s * dt_s
        t.position_ned_m[2] = 0.0
        t.velocity_ned_m_s[:] = [v * c, v * s, 0.0]
        along = (v - previous_speed) / dt_s
        t.acceleration_ned_m_s2[:] = [
            along * c - v * self.yaw_rate_rad_s * s,
            along * s + v * self.yaw_rate_rad_s * c,
            0.0,
        ]
        t.q_wxyz[:] = list(quat_from_yaw(new_yaw))
        t.rates_body_rad_s[:] = [0.0, 0.0, self.yaw_rate_rad_s]
        t.airspeed_m_s = abs(v)
        t.on_ground = True

    def _control(self, setpoint: ControlSetpoint, yaw: float) -> tuple[float, float]:
        """Speed along the heading and yaw rate for a setpoint."""
        if isinstance(setpoint, RatesSetpoint):
            return setpoint.thrust_body[0] * self.speed_max_m_s, setpoint.rates_rad_s[2]
        if isinstance(setpoint, AttitudeSetpoint):
            heading_error = wrap_pi(yaw_from_quat(setpoint.q_wxyz) - yaw)
            return setpoint.thrust_body[0] * self.speed_max_m_s, HEADING_P_PER_S * heading_error
        return self._trajectory_control(setpoint, yaw)

    def _trajectory_control(self, sp: TrajectorySetpoint, yaw: float) -> tuple[float, float]:
        pos = self.truth.position_ned_m
        target, vel = sp.position_ned_m, sp.velocity_ned_m_s
        if is_finite(target[0]) and is_finite(target[1]):
            dn, de = target[0] - pos[0], target[1] - pos[1]
            distance = math.hypot(dn, de)
            if distance < ARRIVAL_RADIUS_M:
                if is_finite(sp.yaw_rad):
                    return 0.0, HEADING_P_PER_S * wrap_pi(sp.yaw_rad - yaw)
                return 0.0, 0.0
            cruise = sp.max_speed_xy_m_s if is_finite(sp.max_speed_xy_m_s) else self.speed_trim_m_s
            # arrive: the speed from which the deceleration limit stops us well inside the
            # arrival radius (aiming at its edge would approach it forever)
            aim_m = max(distance - 0.5 * ARRIVAL_RADIUS_M, 0.0)
            arrive = math.sqrt(2.0 * self.decel_m_s2 * aim_m)
            return self._steer(math.atan2(de, dn), min(cruise, arrive), yaw)
        if is_finite(vel[0]) and is_finite(vel[1]):
            speed = math.hypot(vel[0], vel[1])
            if speed < 0.05:
                return 0.0, 0.0
            return self._steer(math.atan2(vel[1], vel[0]), speed, yaw)
        if is_finite(sp.yawspeed_rad_s):
            return 0.0, sp.yawspeed_rad_s
        return 0.0, 0.0

    def _steer(self, course_rad: float, speed_m_s: float, yaw: float) -> tuple[float, float]:
        """Turn towards the course; drive only as much as the heading is right."""
        error = wrap_pi(course_rad - yaw)
        return speed_m_s * max(0.0, math.cos(error)), HEADING_P_PER_S * error

    def request_transition(self, to_fixed_wing: bool, immediate: bool) -> None:
        """Not a VTOL: nothing to do."""

    def reset(self, position_ned_m: list[float], yaw_rad: float) -> None:
        t = self.truth
        t.position_ned_m[:] = [float(position_ned_m[0]), float(position_ned_m[1]), 0.0]
        t.velocity_ned_m_s[:] = [0.0, 0.0, 0.0]
        t.acceleration_ned_m_s2[:] = [0.0, 0.0, 0.0]
        t.rates_body_rad_s[:] = [0.0, 0.0, 0.0]
        t.q_wxyz[:] = list(quat_from_yaw(yaw_rad))
        t.airspeed_m_s = 0.0
        t.on_ground = True
        self.speed_m_s = 0.0
        self.yaw_rate_rad_s = 0.0
        self.actuator_outputs = [0.0, 0.0]
        self.power_fraction = 0.0
