"""Fixed-wing airframe: a wing and a pusher on a rigid body, with runway ground handling."""

from __future__ import annotations

import math

from sim.control.fw_control import FixedWingControl, SurfacesThrottle
from sim.control.setpoint_guard import safe_setpoint
from sim.lib.geo import SIH_LOC_H0_M
from sim.lib.params import ParamReader
from sim.lib.quat import (
    Vec3,
    euler_from_quat,
    quat_from_euler,
    rotate_body_to_ned,
    rotate_ned_to_body,
)
from sim.lib.topics import ControlSetpoint, LandingStatus, VehicleStateTruth, VtolState
from sim.models.multicopter import PARAM_REFRESH_PERIOD_S, make_rigid_body, refresh_rigid_body
from sim.physics.rigid_body import GRAVITY_M_S2, RigidBody
from sim.physics.sih_aero import SihFixedWingAero

# Wheels: rolling resistance on the runway, brakes when no thrust is wanted, no side slip
ROLLING_FRICTION = 0.03
BRAKING_FRICTION = 0.3
BRAKE_BELOW_THROTTLE = 0.05


class Airframe:
    """What the plane and the VTOL share: SIH's fixed-wing aerodynamics, a pusher of
    `pusher_t_max` × SIH_T_MAX (lagged by SIH_T_TAU), a rigid body and airspeed. As in
    SIH, the plane's tailplane and fin sit in the pusher's slipstream, the VTOL's do not.
    With wheels it rolls along its heading on the ground (plane); without, it sits still on
    skids (VTOL)."""

    def __init__(
        self, params: ParamReader, pusher_t_max: float, slipstream: bool, wheels: bool
    ) -> None:
        self.params = params
        self.aero = SihFixedWingAero()
        self.pusher_t_max = pusher_t_max
        self.slipstream = slipstream
        self.wheels = wheels
        self.truth = VehicleStateTruth()
        self.body: RigidBody = make_rigid_body(self.truth, params)
        self.body.ground_friction = not wheels
        self.pusher = 0.0
        self._since_refresh_s = 0.0
        self.refresh_params()

    def refresh_params(self) -> None:
        refresh_rigid_body(self.body, self.params)
        self.pusher_max_n = self.pusher_t_max * float(self.params.get("SIH_T_MAX"))
        self.tau_s = max(float(self.params.get("SIH_T_TAU")), 1e-3)

    def tick_params(self, dt_s: float) -> bool:
        """Refresh parameters every PARAM_REFRESH_PERIOD_S; True when it did."""
        self._since_refresh_s += dt_s
        if self._since_refresh_s < PARAM_REFRESH_PERIOD_S:
            return False
        self._since_refresh_s = 0.0
        self.refresh_params()
        return True

    def aero_and_pusher(
        self, dt_s: float, surfaces: SurfacesThrottle
    ) -> tuple[Vec3, Vec3]:
        """Aerodynamic forces/moments plus the lagged pusher thrust, force in body axes."""
        t = self.truth
        v_body = rotate_ned_to_body(t.q_wxyz, t.velocity_ned_m_s)
        t.airspeed_m_s = math.sqrt(v_body[0] ** 2 + v_body[1] ** 2 + v_body[2] ** 2)
        rates = t.rates_body_rad_s
        self.pusher += (surfaces.throttle - self.pusher) * min(1.0, dt_s / self.tau_s)
        slipstream_n = self.pusher * float(self.params.get("SIH_T_MAX")) if self.slipstream else 0.0
        force, moment = self.aero.forces_and_moments(
            (v_body[0], v_body[1], v_body[2]), (rates[0], rates[1], rates[2]),
            SIH_LOC_H0_M - t.position_ned_m[2],
            surfaces.aileron, surfaces.elevator, surfaces.rudder, slipstream_n,
        )
        return (force[0] + self.pusher * self.pusher_max_n, force[1], force[2]), moment

    def integrate(self, dt_s: float, force_body_n: Vec3, moment_body_n_m: Vec3) -> None:
        t = self.truth
        force = rotate_body_to_ned(t.q_wxyz, force_body_n)
        if self.wheels and t.on_ground:
            braking = self.pusher < BRAKE_BELOW_THROTTLE
            friction = BRAKING_FRICTION if braking else ROLLING_FRICTION
            force = self._with_wheel_friction(dt_s, force, friction)
        self.body.step(dt_s, force, moment_body_n_m)
        if self.wheels and t.on_ground:
            self._roll_along_heading()

    def _with_wheel_friction(self, dt_s: float, force_ned: Vec3, friction: float) -> Vec3:
        v = self.truth.velocity_ned_m_s
        speed = math.hypot(v[0], v[1])
        if speed < 1e-3:
            return force_ned
        normal = max(0.0, self.body.mass_kg * GRAVITY_M_S2 + force_ned[2])
        # never more than what stops the vehicle within this step (no reversing)
        k = min(friction * normal, self.body.mass_kg * speed / dt_s) / speed
        return (force_ned[0] - k * v[0], force_ned[1] - k * v[1], force_ned[2])

    def _roll_along_heading(self) -> None:
        """On the ground the wheels keep the wings level and the vehicle moving along its
        nose; the nose may rise (rotation on the main wheels), never sink below level."""
        t = self.truth
        _, pitch, yaw = euler_from_quat(t.q_wxyz)
        v = t.velocity_ned_m_s
        forward = max(0.0, v[0] * math.cos(yaw) + v[1] * math.sin(yaw))
        v[0], v[1] = forward * math.cos(yaw), forward * math.sin(yaw)
        w = t.rates_body_rad_s
        w[0] = 0.0
        if pitch <= 0.0:
            pitch = 0.0
            w[1] = max(0.0, w[1])
        t.q_wxyz[:] = list(quat_from_euler(0.0, pitch, yaw))

    def reset(self, position_ned_m: list[float], yaw_rad: float) -> None:
        self.body.reset(position_ned_m, yaw_rad)
        self.pusher = 0.0


class FixedWingModel:
    """The plane: outputs [pusher, aileron, elevator, rudder] (PX4 order: motors, then servos)."""

    name = "plane"
    mav_type = 1  # MAV_TYPE_FIXED_WING
    is_vtol = False
    in_fixed_wing_flight = True
    vtol_state = VtolState.UNDEFINED

    def __init__(self, params: ParamReader) -> None:
        self.params = params
        # SIH's airplane: the pusher gives SIH_T_MAX
        self.frame = Airframe(params, pusher_t_max=1.0, slipstream=True, wheels=True)
        self.truth = self.frame.truth
        self.control = FixedWingControl(
            params, self.frame.body.mass_kg, self.frame.pusher_max_n
        )
        self.actuator_outputs = [0.0, 0.0, 0.0, 0.0]
        self.power_fraction = 0.0
        self.landing: LandingStatus | None = None  # no multicopter land detection

    def step(self, dt_s: float, armed: bool, setpoint: ControlSetpoint | None) -> None:
        if self.frame.tick_params(dt_s):
            self.control.refresh_params()
            self.control.mass_kg = self.frame.body.mass_kg
            self.control.thrust_max_n = self.frame.pusher_max_n
        if armed and setpoint is not None:
            surfaces = self.control.update(dt_s, self.truth, safe_setpoint(setpoint, self.truth))
        else:
            surfaces = SurfacesThrottle()
            self.control.reset()
        self.actuator_outputs = [
            surfaces.throttle, surfaces.aileron, surfaces.elevator, surfaces.rudder
        ]
        force, moment = self.frame.aero_and_pusher(dt_s, surfaces)
        self.power_fraction = self.frame.pusher
        self.frame.integrate(dt_s, force, moment)

    def request_transition(self, to_fixed_wing: bool, immediate: bool) -> None:
        """Not a VTOL: nothing to do."""

    def reset(self, position_ned_m: list[float], yaw_rad: float) -> None:
        self.frame.reset(position_ned_m, yaw_rad)
        self.control.reset()
        self.actuator_outputs = [0.0, 0.0, 0.0, 0.0]
        self.power_fraction = 0.0
