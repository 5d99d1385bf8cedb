"""6-DOF rigid body on flat ground, after PX4's simulator_sih.

Forces are summed in NED, moments in body axes; the integration is semi-implicit Euler at
the physics rate. Ground level is NED down = 0: the body cannot sink below it, and while the
net force presses it down it sits still, level, with its heading kept (friction), like SIH's
ground contact. Every state stays finite: an overflow resets to a safe resting state rather
than spreading NaN into telemetry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from sim.lib.quat import Vec3, quat_from_yaw, quat_integrate, yaw_from_quat
from sim.lib.topics import VehicleStateTruth

GRAVITY_M_S2 = 9.80665
# Beyond these the model has blown up; clamping keeps telemetry finite and plausible
MAX_SPEED_M_S = 200.0
MAX_RATE_RAD_S = 50.0


@dataclass(eq=False)
class RigidBody:
    """Mass, diagonal inertia and linear drag (SIH_KDV, SIH_KDW), integrated in place."""

    truth: VehicleStateTruth
    mass_kg: float
    inertia_kg_m2: Vec3
    drag_velocity_n_s_m: float
    drag_rate_n_m_s_rad: float
    ground_friction: bool = field(default=True, init=False)

    def step(self, dt_s: float, force_ned_n: Vec3, moment_body_n_m: Vec3) -> None:
        t = self.truth
        m = self.mass_kg
        vx, vy, vz = t.velocity_ned_m_s
        kdv = self.drag_velocity_n_s_m
        ax = (force_ned_n[0] - kdv * vx) / m
        ay = (force_ned_n[1] - kdv * vy) / m
        az = (force_ned_n[2] - kdv * vz) / m + GRAVITY_M_S2

        p, q, r = t.rates_body_rad_s
        ixx, iyy, izz = self.inertia_kg_m2
        kdw = self.drag_rate_n_m_s_rad
        # Euler's equations with the gyroscopic term ω × Iω
        dp = (moment_body_n_m[0] - kdw * p - (izz - iyy) * q * r) / ixx
        dq = (moment_body_n_m[1] - kdw * q - (ixx - izz) * p * r) / iyy
        dr = (moment_body_n_m[2] - kdw * r - (iyy - ixx) * p * q) / izz
        p += dp * dt_s
        q += dq * dt_s
        r += dr * dt_s

        vx += ax * dt_s
        vy += ay * dt_s
        vz += az * dt_s
        pos = t.position_ned_m
        n = pos[0] + vx * dt_s
        e = pos[1] + vy * dt_s
        d = pos[2] + vz * dt_s
        q_new = quat_integrate(t.q_wxyz, (p, q, r), dt_s)

        if d >= 0.0:
            d = 0.0
            if vz > 0.0:
                vz = 0.0
            pressed_down = force_ned_n[2] + m * GRAVITY_M_S2 >= 0.0
            if pressed_down and self.ground_friction:
                n, e = pos[0], pos[1]
                vx = vy = vz = 0.0
                ax = ay = az = 0.0
                p = q = r = 0.0
                q_new = quat_from_yaw(yaw_from_quat(q_new))
            elif pressed_down:
                az = 0.0
            t.on_ground = pressed_down
        else:
            t.on_ground = False

        # one sum carries any NaN or inf of its terms, and x - x is 0 only for finite x
        total = n + e + d + vx + vy + vz + p + q + r + ax + ay + az + sum(q_new)
        if total - total != 0.0:
            self._reset_to_rest()
            return
        t.position_ned_m[0] = n
        t.position_ned_m[1] = e
        t.position_ned_m[2] = d
        v = t.velocity_ned_m_s
        vmax = MAX_SPEED_M_S
        v[0] = vmax if vx > vmax else -vmax if vx < -vmax else vx
        v[1] = vmax if vy > vmax else -vmax if vy < -vmax else vy
        v[2] = vmax if vz > vmax else -vmax if vz < -vmax else vz
        a = t.acceleration_ned_m_s2
        a[0] = ax
        a[1] = ay
        a[2] = az
        w = t.rates_body_rad_s
        wmax = MAX_RATE_RAD_S
        w[0] = wmax if p > wmax else -wmax if p < -wmax else p
        w[1] = wmax if q > wmax else -wmax if q < -wmax else q
        w[2] = wmax if r > wmax else -wmax if r < -wmax else r
        t.q_wxyz[0], t.q_wxyz[1], t.q_wxyz[2], t.q_wxyz[3] = q_new

    def _reset_to_rest(self) -> None:
        t = self.truth
        pos = t.position_ned_m
        for i in range(3):
            if not math.isfinite(pos[i]):
                pos[i] = 0.0
        pos[2] = min(pos[2], 0.0)
        t.velocity_ned_m_s[:] = [0.0, 0.0, 0.0]
        t.acceleration_ned_m_s2[:] = [0.0, 0.0, 0.0]
        t.rates_body_rad_s[:] = [0.0, 0.0, 0.0]
        yaw = yaw_from_quat(t.q_wxyz)
        t.q_wxyz[:] = list(quat_from_yaw(yaw if math.isfinite(yaw) else 0.0))

    def reset(self, position_ned_m: list[float], yaw_rad: float) -> None:
        t = self.truth
        t.position_ned_m[:] = [float(v) for v in position_ned_m]
        t.position_ned_m[2] = min(t.position_ned_m[2], 0.0)
        t.velocity_ned_m_s[:] = [0.0, 0.0, 0.0]
        t.acceleration_ned_m_s2[:] = [0.0, 0.0, 0.0]
        t.rates_body_rad_s[:] = [0.0, 0.0, 0.0]
        t.q_wxyz[:] = list(quat_from_yaw(yaw_rad))
        t.airspeed_m_s = 0.0
        t.on_ground = t.position_ned_m[2] >= 0.0
