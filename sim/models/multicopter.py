"""Multicopter airframe: rotors on a rigid body, SIH style, driven by the PX4-like cascade."""

from __future__ import annotations

import math

from sim.control.mc_control import MulticopterControl
from sim.control.setpoint_guard import safe_setpoint
from sim.lib.params import ParamReader
from sim.lib.quat import rotate_body_to_ned
from sim.lib.topics import ControlSetpoint, LandingStatus, VehicleStateTruth, VtolState
from sim.physics.mixer import Mixer
from sim.physics.rigid_body import GRAVITY_M_S2, RigidBody

PARAM_REFRESH_PERIOD_S = 0.2


class RotorSet:
    """Rotors with a first-order lag (SIH_T_TAU): thrust along body -z and their moments."""

    def __init__(self, mixer: Mixer, params: ParamReader) -> None:
        self.mixer = mixer
        self.params = params
        self.lagged = [0.0] * mixer.rotor_count
        self.refresh_params()

    def refresh_params(self) -> None:
        p = self.params
        self.t_max_n = float(p.get("SIH_T_MAX"))
        self.q_max_n_m = float(p.get("SIH_Q_MAX"))
        self.tau_s = max(float(p.get("SIH_T_TAU")), 1e-3)
        # SIH's lever arms are the roll/pitch distances of a quad-X rotor; other
        # geometries put their rotors on a circle through the same points.
        arm_x = float(p.get("SIH_L_PITCH")) * math.sqrt(2.0)
        arm_y = float(p.get("SIH_L_ROLL")) * math.sqrt(2.0)
        self.roll_arm_m = []
        self.pitch_arm_m = []
        self.spin = []
        for rotor in self.mixer.rotors:
            a = math.radians(rotor.angle_deg)
            self.pitch_arm_m.append(arm_x * math.cos(a))
            self.roll_arm_m.append(-arm_y * math.sin(a))
            self.spin.append(float(rotor.spin))

    def hover_thrust(self, mass_kg: float) -> float:
        return min(1.0, mass_kg * GRAVITY_M_S2 / (self.t_max_n * self.mixer.rotor_count))

    def advance(self, dt_s: float, commanded: list[float]) -> tuple[float, float, float, float]:
        """Lag the outputs; return (thrust N, roll, pitch, yaw moment N·m)."""
        k = min(1.0, dt_s / self.tau_s)
        u = self.lagged
        total = roll = pitch = yaw = 0.0
        for i, cmd in enumerate(commanded):
            ui = u[i] + (cmd - u[i]) * k
            u[i] = ui
            total += ui
            roll += self.roll_arm_m[i] * ui
            pitch += self.pitch_arm_m[i] * ui
            yaw += self.spin[i] * ui
        t = self.t_max_n
        return total * t, roll * t, pitch * t, yaw * self.q_max_n_m

    def stop(self) -> None:
        self.lagged = [0.0] * len(self.lagged)


def make_rigid_body(truth: VehicleStateTruth, params: ParamReader) -> RigidBody:
    return RigidBody(
        truth,
        mass_kg=float(params.get("SIH_MASS")),
        inertia_kg_m2=(
            float(params.get("SIH_IXX")),
            float(params.get("SIH_IYY")),
            float(params.get("SIH_IZZ")),
        ),
        drag_velocity_n_s_m=float(params.get("SIH_KDV")),
        drag_rate_n_m_s_rad=float(params.get("SIH_KDW")),
    )


def refresh_rigid_body(body: RigidBody, params: ParamReader) -> None:
    body.mass_kg = max(float(params.get("SIH_MASS")), 1e-3)
    body.inertia_kg_m2 = (
        max(float(params.get("SIH_IXX")), 1e-5),
        max(float(params.get("SIH_IYY")), 1e-5),
        max(float(params.get("SIH_IZZ")), 1e-5),
    )
    body.drag_velocity_n_s_m = float(params.get("SIH_KDV"))
    body.drag_rate_n_m_s_rad = float(params.get("SIH_KDW"))


class MulticopterModel:
    """quad (4x), hexa (6x), octo (8x): the AirframeModel of a multicopter."""

    is_vtol = False
    in_fixed_wing_flight = False

    def __init__(self, name: str, mav_type: int, geometry: str, params: ParamReader) -> None:
        self.name = name
        self.mav_type = mav_type
        self.params = params
        self.truth = VehicleStateTruth()
        self.vtol_state = VtolState.UNDEFINED
        self.body = make_rigid_body(self.truth, params)
        self.rotors = RotorSet(Mixer(geometry), params)
        self.control = MulticopterControl(params)
        self.actuator_outputs = [0.0] * self.rotors.mixer.rotor_count
        self.power_fraction = 0.0
        self._since_refresh_s = 0.0

    @property
    def landing(self) -> LandingStatus:
        return self.control.landing

    def step(self, dt_s: float, armed: bool, setpoint: ControlSetpoint | None) -> None:
        self.control.note_armed(dt_s, armed)
        self._since_refresh_s += dt_s
        if self._since_refresh_s >= PARAM_REFRESH_PERIOD_S:
            self._since_refresh_s = 0.0
            refresh_rigid_body(self.body, self.params)
            self.rotors.refresh_params()
        mixer = self.rotors.mixer
        if armed and setpoint is not None:
            cmd = self.control.update(
                dt_s,
                self.truth,
                safe_setpoint(setpoint, self.truth),
                self.rotors.hover_thrust(self.body.mass_kg),
            )
            outputs = mixer.mix(cmd.roll, cmd.pitch, cmd.yaw, cmd.thrust)
            self.control.mixer_saturated = mixer.saturated
        else:
            outputs = [0.0] * mixer.rotor_count
            self.control.reset()
        self.actuator_outputs = outputs
        thrust_n, roll, pitch, yaw = self.rotors.advance(dt_s, outputs)
        self.power_fraction = sum(self.rotors.lagged) / mixer.rotor_count
        force = rotate_body_to_ned(self.truth.q_wxyz, (0.0, 0.0, -thrust_n))
        self.body.step(dt_s, force, (roll, pitch, yaw))
        v = self.truth.velocity_ned_m_s
        # still air: what a pitot tube would read is the speed over ground
        self.truth.airspeed_m_s = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])

    def request_transition(self, to_fixed_wing: bool, immediate: bool) -> None:
        """Not a VTOL: nothing to do (the commander does not ack the command either)."""

    def reset(self, position_ned_m: list[float], yaw_rad: float) -> None:
        self.body.reset(position_ned_m, yaw_rad)
        self.rotors.stop()
        self.control.reset()
        self.actuator_outputs = [0.0] * self.rotors.mixer.rotor_count
        self.power_fraction = 0.0
