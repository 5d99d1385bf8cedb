"""A simple wing: lift with stall, induced and parasitic drag, control-surface moments.

Linear lift up to the stall angle, blended into flat-plate lift beyond it (Beard & McLain,
"Small Unmanned Aircraft", ch. 4), so the coefficients stay smooth and bounded at any angle.
Still air: the airspeed is the body velocity. Forces and moments are in body axes (FRD).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim.lib.quat import Vec3

AIR_DENSITY_KG_M3 = 1.225
_STALL_BLEND_RATE = 50.0
SIDESLIP_STALL_RAD = math.radians(15.0)


@dataclass(frozen=True)
class WingGeometry:
    """Aerodynamic data of a small electric airframe. Surface deflections are normalised:
    +1 aileron rolls right, +1 elevator pitches the nose up, +1 rudder yaws right."""

    area_m2: float
    span_m: float
    chord_m: float
    cl0: float = 0.3
    cl_alpha_per_rad: float = 5.0
    stall_angle_rad: float = math.radians(15.0)
    cd0: float = 0.03
    oswald: float = 0.8
    cy_beta: float = -0.6
    cl_roll_aileron: float = 0.1
    cl_roll_damping: float = -0.5
    cl_roll_beta: float = -0.05
    cm0: float = 0.0
    cm_alpha: float = -1.0
    cm_elevator: float = 0.4
    cm_pitch_damping: float = -12.0
    cn_beta: float = 0.08
    cn_rudder: float = 0.06
    cn_yaw_damping: float = -0.15

    @property
    def induced_drag_factor(self) -> float:
        aspect_ratio = self.span_m * self.span_m / self.area_m2
        return 1.0 / (math.pi * self.oswald * aspect_ratio)


def angle_of_attack_rad(velocity_body_m_s: Vec3) -> float:
    u, _, w = velocity_body_m_s
    return math.atan2(w, u) if (u != 0.0 or w != 0.0) else 0.0


def lift_coefficient(wing: WingGeometry, alpha_rad: float) -> float:
    a0 = wing.stall_angle_rad
    m = _STALL_BLEND_RATE
    # sigma → 0 in the attached-flow range, → 1 past the stall angle either side
    e1 = math.exp(min(-m * (alpha_rad - a0), 60.0))
    e2 = math.exp(min(m * (alpha_rad + a0), 60.0))
    sigma = (1.0 + e1 + e2) / ((1.0 + e1) * (1.0 + e2))
    linear = wing.cl0 + wing.cl_alpha_per_rad * alpha_rad
    sa, ca = math.sin(alpha_rad), math.cos(alpha_rad)
    flat_plate = 2.0 * math.copysign(1.0, alpha_rad) * sa * sa * ca
    return (1.0 - sigma) * linear + sigma * flat_plate


def forces_and_moments(
    wing: WingGeometry,
    velocity_body_m_s: Vec3,
    rates_body_rad_s: Vec3,
    aileron: float,
    elevator: float,
    rudder: float,
) -> tuple[Vec3, Vec3]:
    """Aerodynamic force (N) and moment (N·m) in body axes."""
    u, v, w = velocity_body_m_s
    airspeed = math.sqrt(u * u + v * v + w * w)
    if airspeed < 0.1:
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    alpha = math.atan2(w, u)
    # fin and dihedral effects stall too: beyond a moderate sideslip they stop growing
    beta = math.asin(max(-1.0, min(1.0, v / airspeed)))
    beta = max(-SIDESLIP_STALL_RAD, min(SIDESLIP_STALL_RAD, beta))
    qbar_s = 0.5 * AIR_DENSITY_KG_M3 * airspeed * airspeed * wing.area_m2
    cl = lift_coefficient(wing, alpha)
    sa = math.sin(alpha)
    cd = wing.cd0 + wing.induced_drag_factor * cl * cl + 2.0 * sa * sa
    lift = qbar_s * cl
    drag = qbar_s * cd
    ca = math.cos(alpha)
    fx = -drag * ca + lift * sa
    fz = -drag * sa - lift * ca
    fy = qbar_s * wing.cy_beta * beta

    p, q, r = rates_body_rad_s
    b, c = wing.span_m, wing.chord_m
    # rate damping written as ½ρV·S·(b² or c²)/2 so that it needs no division by V
    damp = 0.25 * AIR_DENSITY_KG_M3 * airspeed * wing.area_m2
    roll = qbar_s * b * (wing.cl_roll_aileron * aileron + wing.cl_roll_beta * beta)
    roll += damp * b * b * wing.cl_roll_damping * p
    cm = wing.cm0 + wing.cm_alpha * _clamp_stall(alpha) + wing.cm_elevator * elevator
    pitch = qbar_s * c * cm
    pitch += damp * c * c * wing.cm_pitch_damping * q
    yaw = qbar_s * b * (wing.cn_beta * beta + wing.cn_rudder * rudder)
    yaw += damp * b * b * wing.cn_yaw_damping * r
    return (fx, fy, fz), (roll, pitch, yaw)


def _clamp_stall(alpha_rad: float) -> float:
    # the linear pitch stiffness is meaningless far past the stall; keep it bounded
    limit = math.radians(30.0)
    return max(-limit, min(limit, alpha_rad))
