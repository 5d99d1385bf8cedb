"""PX4 SIH's fixed-wing aerodynamics (simulator_sih/aero.hpp's AeroSeg and sih.cpp's
generate_fw_aerodynamics), for the plane and the standard VTOL.

Each lifting surface is a flat-plate segment (Khan & Nahon's model): lift, drag and pitching
moment over the full 360° of angle of attack, a flap whose deflection shifts the zero-lift
angle and the stall, a propeller slipstream from momentum theory, and ISA air density. The
airframe is SIH's: two wing halves (0.86 m span, 0.21 m chord, -4° zero-lift angle, 3°
dihedral, a third of the chord as aileron), a tailplane with elevator and a fin with rudder
in the propeller's slipstream, and a fuselage. Surface commands in [-1, 1] deflect by
FLAP_MAX (15°): +aileron rolls right, +elevator pitches the nose up, +rudder yaws right.

Forces and moments are in body axes (FRD) about the centre of mass; SIH's first-order drag
(SIH_KDV, SIH_KDW) is the rigid body's. The arithmetic follows PX4's, including its
quirks (its table lookups all return the last column, so every segment stalls at 20°).
"""

from __future__ import annotations

import math

from sim.lib.quat import Vec3

FLAP_MAX_RAD = math.pi / 12.0
SPAN_M = 0.86
MAC_M = 0.21
PROP_RADIUS_M = 0.1

_ETA_POLY = (0.0535, -0.2688, 0.5817)
_P0_PA = 101325.0
_R_AIR = 287.04
_T0_K = 288.15
_TEMP_GRADIENT = -6.5e-3
_KV = math.pi
_CD0 = 0.04
_CD90 = 1.98
_ALPHA_BLEND = math.pi / 18.0
_K0 = 0.87
# aero.hpp's tables hold 10 aspect ratios but are searched as 12 long: the two missing
# entries read 0, so every lookup returns the last column (stall angle 20°)
_AFS_DEG = 20.0


def _sign(x: float) -> float:
    return (x > 0.0) - (x < 0.0)


def _wrap_pi(x: float) -> float:
    return (x + math.pi) % (2.0 * math.pi) - math.pi


def air_density_kg_m3(altitude_amsl_m: float) -> float:
    """ISA density (Cavcar) as AeroSeg computes it."""
    pressure = _P0_PA * math.pow(max(1.0 - 0.0065 * altitude_amsl_m / _T0_K, 1e-6), 5.2561)
    temperature = _T0_K + _TEMP_GRADIENT * altitude_amsl_m
    return pressure / _R_AIR / temperature


def _solve_alpha_eff(kp: float, kv: float, dcl: float, a0: float) -> float:
    """Three Newton steps on AeroSeg's equation 3.15, from a0."""
    a = a0
    for _ in range(3):
        s, c = math.sin(a), math.cos(a)
        f = -kp * s * c * c - kv * abs(s) * s * c - dcl
        df = (kv * abs(s) * s * s - kv * abs(s) * c * c - kp * c * c * c
              + 2.0 * kp * c * s * s - kv * _sign(s) * c * c * s)
        a = a - f / df
    return a


class AeroSeg:
    """One flat-plate aerodynamic segment (AeroSeg in PX4's aero.hpp)."""

    def __init__(
        self,
        span_m: float,
        mac_m: float,
        alpha_0_deg: float,
        p_body_m: Vec3,
        dihedral_deg: float = 0.0,
        aspect_ratio: float = -1.0,
        flap_chord_m: float = 0.0,
        prop_radius_m: float = -1.0,
        cl_alpha: float = 2.0 * math.pi,
    ) -> None:
        self.span = span_m
        self.mac = mac_m
        self.alpha_0 = math.radians(alpha_0_deg)
        self.p_b = p_body_m
        ar = span_m / mac_m if aspect_ratio <= 0.0 else aspect_ratio
        self.kp = cl_alpha / (1.0 + 2.0 * (ar + 4.0) / (ar * (ar + 2.0)))
        self.kn = 0.41 * (1.0 - math.exp(-17.0 / ar))
        self.alpha_max = math.radians(_AFS_DEG)
        self.alpha_min = -self.alpha_max
        self.cf = min(max(flap_chord_m, 0.0), mac_m)
        d = math.radians(dihedral_deg)
        # segment → body: a rotation about x by the dihedral
        self.cd_, self.sd_ = math.cos(d), math.sin(d)
        self.prop_radius = prop_radius_m
        # low-angle coefficients of the last call (PX4 blends against them)
        self.cl = self.cd = self.cm = 0.0

    def forces(
        self, v_body: Vec3, w_body: Vec3, rho: float, deflection_rad: float = 0.0,
        thrust_n: float = 0.0,
    ) -> tuple[Vec3, Vec3]:
        """Force and moment (body axes, about the centre of mass)."""
        px, py, pz = self.p_b
        wx, wy, wz = w_body
        # velocity of the segment: v + w × p, then into the segment frame
        vx = v_body[0] + wy * pz - wz * py
        vy = v_body[1] + wz * px - wx * pz
        vz = v_body[2] + wx * py - wy * px
        cd_, sd_ = self.cd_, self.sd_
        sx = vx
        sz = -sd_ * vy + cd_ * vz
        if self.prop_radius > 1e-4:
            sx += math.sqrt(max(2.0 * thrust_n, 0.0) / (rho * math.pi * self.prop_radius ** 2))
        vxz2 = sx * sx + sz * sz
        if vxz2 < 0.01:
            return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        alpha = _wrap_pi(math.atan2(sz, sx) - self.alpha_0)
        self._coefficients(alpha, deflection_rad)
        q_s = 0.5 * rho * vxz2 * self.span * self.mac
        sa, ca = math.sin(alpha), math.cos(alpha)
        fx_s = q_s * (self.cl * sa - self.cd * ca)
        fz_s = q_s * (-self.cl * ca - self.cd * sa)
        # segment → body (y_s is 0)
        fx, fy, fz = fx_s, -sd_ * fz_s, cd_ * fz_s
        my_s = q_s * self.mac * self.cm
        mx = 0.0 + (py * fz - pz * fy)
        my = cd_ * my_s + (pz * fx - px * fz)
        mz = sd_ * my_s + (px * fy - py * fx)
        return (fx, fy, fz), (mx, my, mz)

    def _f_cl(self, a: float) -> float:
        s, c = math.sin(a), math.cos(a)
        return self.kp * s * c * c + _KV * abs(s) * s * c

    def _f_cm(self, a: float) -> float:
        s = math.sin(a)
        return 0.17 * _KV * abs(s) * s

    def _coefficients(self, a: float, deflection: float) -> None:
        mac, cf = self.mac, self.cf
        if cf / mac < 0.999:
            def_a = min(abs(deflection), math.radians(70.0))
            eta_f = def_a * def_a * _ETA_POLY[0] + def_a * _ETA_POLY[1] + _ETA_POLY[2]
            theta_f = math.acos(2.0 * cf / mac - 1.0)
            tau_f = 1.0 - (theta_f - math.sin(theta_f)) / math.pi
            delta_cl = self.kp * tau_f * eta_f * deflection
            dcl_max = (1.0 - cf / mac) * delta_cl
            alf0eff = _solve_alpha_eff(self.kp, _KV, delta_cl, self.alpha_0)
            alpha_eff = a - alf0eff
            cl_max = self._f_cl(self.alpha_max - self.alpha_0) + dcl_max
            alpha_eff_max = alf0eff - _solve_alpha_eff(
                self.kp, _KV, cl_max, self.alpha_max - self.alpha_0)
            cl_min = self._f_cl(self.alpha_min - self.alpha_0) + dcl_max
            alpha_eff_min = alf0eff - _solve_alpha_eff(
                self.kp, _KV, cl_min, self.alpha_min - self.alpha_0)
        else:
            alpha_eff = a + deflection
            alpha_eff_max, alpha_eff_min = self.alpha_max, self.alpha_min
        cl_high, cd_high, cm_high = self._high_aoa(alpha_eff, deflection)
        cl_low = self._f_cl(alpha_eff)
        # PX4 takes the induced drag from the high-angle lift coefficient just computed
        cd_low = _CD0 + abs(cl_high * math.tan(alpha_eff))
        cm_low = -self._f_cm(alpha_eff)
        if alpha_eff > 0.0:
            blend = 0.5 * (1.0 - math.tanh(4.0 * (alpha_eff - alpha_eff_max) / _ALPHA_BLEND))
        else:
            blend = 0.5 * (1.0 - math.tanh(-4.0 * (alpha_eff - alpha_eff_min) / _ALPHA_BLEND))
        self.cl = cl_low * blend + cl_high * (1.0 - blend)
        self.cd = cd_low * blend + cd_high * (1.0 - blend)
        self.cm = cm_low * blend + cm_high * (1.0 - blend)

    def _high_aoa(self, a: float, deflection: float) -> tuple[float, float, float]:
        mac, cf = self.mac, self.cf
        mac_eff = math.sqrt(
            (mac - cf) ** 2 + cf * cf + 2.0 * (mac - cf) * cf * math.cos(abs(deflection)))
        a += math.asin(max(-1.0, min(1.0, cf / mac_eff * math.sin(deflection))))
        cd90_eff = _CD90 + 0.21 * deflection - 0.0426 * deflection * deflection
        sa, ca = math.sin(a), math.cos(a)
        cn = cd90_eff * sa * (1.0 / (0.56 + 0.44 * abs(sa)) - self.kn)
        ct = 0.5 * _CD0 * ca
        cl = cn * ca - ct * sa
        cd = cn * sa + ct * ca
        cm = -cn * (0.25 - 7.0 / 40.0 * (1.0 - 2.0 / math.pi * abs(a)))
        return cl, cd, cm


class SihFixedWingAero:
    """SIH's fixed wing: wing halves, tailplane, fin and fuselage (sih.hpp)."""

    def __init__(self) -> None:
        half = SPAN_M / 2.0
        self.wing_l = AeroSeg(half, MAC_M, -4.0, (0.0, -SPAN_M / 4.0, 0.0), 3.0,
                              SPAN_M / MAC_M, MAC_M / 3.0)
        self.wing_r = AeroSeg(half, MAC_M, -4.0, (0.0, SPAN_M / 4.0, 0.0), -3.0,
                              SPAN_M / MAC_M, MAC_M / 3.0)
        self.tailplane = AeroSeg(0.3, 0.1, 0.0, (-0.4, 0.0, 0.0), 0.0, -1.0, 0.05,
                                 PROP_RADIUS_M)
        self.fin = AeroSeg(0.25, 0.18, 0.0, (-0.45, 0.0, -0.1), -90.0, -1.0, 0.12,
                           PROP_RADIUS_M)
        self.fuselage = AeroSeg(0.2, 0.8, 0.0, (0.0, 0.0, 0.0), -90.0)

    def forces_and_moments(
        self,
        v_body: Vec3,
        w_body: Vec3,
        altitude_amsl_m: float,
        aileron: float,
        elevator: float,
        rudder: float,
        slipstream_thrust_n: float,
    ) -> tuple[Vec3, Vec3]:
        """generate_fw_aerodynamics without the KDV/KDW terms."""
        rho = air_density_kg_m3(altitude_amsl_m)
        parts = (
            self.wing_l.forces(v_body, w_body, rho, aileron * FLAP_MAX_RAD),
            self.wing_r.forces(v_body, w_body, rho, -aileron * FLAP_MAX_RAD),
            self.tailplane.forces(v_body, w_body, rho, -elevator * FLAP_MAX_RAD,
                                  slipstream_thrust_n),
            self.fin.forces(v_body, w_body, rho, rudder * FLAP_MAX_RAD, slipstream_thrust_n),
            self.fuselage.forces(v_body, w_body, rho),
        )
        fx = sum(f[0] for f, _ in parts)
        fy = sum(f[1] for f, _ in parts)
        fz = sum(f[2] for f, _ in parts)
        mx = sum(m[0] for _, m in parts)
        my = sum(m[1] for _, m in parts)
        mz = sum(m[2] for _, m in parts)
        return (fx, fy, fz), (mx, my, mz)
