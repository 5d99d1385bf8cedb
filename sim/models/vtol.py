"""Standard VTOL: four lift rotors (quad X) + a pusher + a wing, after PX4's vtol_att_control.

`VtolTransition` is the transition logic of PX4_NOTES "VTOL" (standard.cpp):
- front: the pusher ramps at VT_PSHER_SLEW up to VT_F_TRANS_THR while the lift rotors hold
  height; done when airspeed ≥ VT_ARSP_TRANS after at least VT_TRANS_MIN_TM (without an
  airspeed sensor, FW_USE_AIRSPD 0: after VT_F_TR_OL_TM); after VT_TRANS_TIMEOUT without
  that, quadchute back to MC.
- back: pusher off; the lift rotors' torque and thrust ramp in over VT_B_TRANS_RAMP while
  the surfaces hold the wings level, so the airframe's drag does the braking; done
  (standard.cpp's exit conditions) once the forward speed (the velocity along the body x
  axis) is below MPC_XY_CRUISE, once more than
  VT_B_TRANS_DUR has passed, or at once when disarmed or landed (can_transition_on_ground).
"""

from __future__ import annotations

import math

from sim.control.fw_control import FixedWingControl, SurfacesThrottle
from sim.control.mc_control import MulticopterControl
from sim.control.setpoint_guard import safe_setpoint
from sim.lib.params import ParamReader
from sim.lib.quat import euler_from_quat, rotate_ned_to_body, yaw_from_quat
from sim.lib.topics import ControlSetpoint, LandingStatus, TrajectorySetpoint, VtolState
from sim.models.fixed_wing import Airframe
from sim.models.multicopter import RotorSet
from sim.physics.mixer import Mixer

MAV_TYPE_VTOL_FIXEDROTOR = 22


class VtolTransition:
    """MC → TRANSITION_TO_FW → FW → TRANSITION_TO_MC → MC, with quadchute on timeout."""

    def __init__(self, params: ParamReader) -> None:
        self.params = params
        self.state = VtolState.MC
        self.elapsed_s = 0.0
        self.pusher_throttle = 0.0
        self.quadchutes = 0

    def request(self, to_fixed_wing: bool, immediate: bool, airborne: bool) -> None:
        s = self.state
        if to_fixed_wing:
            if not airborne or s in (VtolState.FW, VtolState.TRANSITION_TO_FW):
                return
            self._enter(VtolState.FW if immediate else VtolState.TRANSITION_TO_FW)
        else:
            if s == VtolState.MC:
                return
            # an unfinished front transition is simply abandoned, like PX4 does
            direct = immediate or s == VtolState.TRANSITION_TO_FW
            self._enter(VtolState.MC if direct else VtolState.TRANSITION_TO_MC)

    def _enter(self, state: VtolState) -> None:
        self.state = state
        self.elapsed_s = 0.0
        if state != VtolState.FW:
            self.pusher_throttle = 0.0

    def update(
        self,
        dt_s: float,
        airspeed_m_s: float,
        forward_speed_m_s: float,
        disarmed_or_landed: bool = False,
    ) -> VtolState:
        self.elapsed_s += dt_s
        p = self.params.get
        if self.state == VtolState.TRANSITION_TO_FW:
            self.pusher_throttle = min(
                p("VT_F_TRANS_THR"), self.pusher_throttle + p("VT_PSHER_SLEW") * dt_s
            )
            if p("FW_USE_AIRSPD"):
                fast_enough = airspeed_m_s >= p("VT_ARSP_TRANS")
            else:
                # no airspeed sensor: PX4 trusts the clock (open-loop transition)
                fast_enough = self.elapsed_s >= p("VT_F_TR_OL_TM")
            if self.elapsed_s >= p("VT_TRANS_MIN_TM") and fast_enough:
                self._enter(VtolState.FW)
            elif self.elapsed_s >= p("VT_TRANS_TIMEOUT"):
                self.quadchutes += 1
                self._enter(VtolState.MC)
        elif self.state == VtolState.TRANSITION_TO_MC and self.back_transition_done(
            forward_speed_m_s, disarmed_or_landed
        ):
            self._enter(VtolState.MC)
        return self.state

    def mc_weight(self) -> float:
        """How much of the multicopter controller's torque and thrust reaches the lift
        rotors (standard.cpp's mc weights): all of it in MC and in the front transition;
        in the back transition it ramps in over VT_B_TRANS_RAMP while the surfaces fly."""
        if self.state != VtolState.TRANSITION_TO_MC:
            return 1.0
        ramp_s = self.params.get("VT_B_TRANS_RAMP")
        return min(1.0, self.elapsed_s / ramp_s) if ramp_s > 1e-6 else 1.0

    def back_transition_done(self, forward_speed_m_s: float, disarmed_or_landed: bool) -> bool:
        """PX4's exit from TRANSITION_TO_MC: slow enough, out of time, or on the ground."""
        slow_enough = forward_speed_m_s < self.params.get("MPC_XY_CRUISE")
        out_of_time = self.elapsed_s > self.params.get("VT_B_TRANS_DUR")
        return disarmed_or_landed or slow_enough or out_of_time


class VtolModel:
    """Outputs [lift rotors 0-3, pusher, aileron, elevator, rudder]."""

    name = "vtol"
    mav_type = MAV_TYPE_VTOL_FIXEDROTOR
    is_vtol = True

    def __init__(self, params: ParamReader) -> None:
        self.params = params
        # SIH's standard VTOL: the pusher gives 2 × SIH_T_MAX, out of the tail's slipstream
        self.frame = Airframe(params, pusher_t_max=2.0, slipstream=False, wheels=False)
        self.truth = self.frame.truth
        self.rotors = RotorSet(Mixer("4x"), params)
        self.mc = MulticopterControl(params)
        self.fw = FixedWingControl(params, self.frame.body.mass_kg, self.frame.pusher_max_n)
        self.transition = VtolTransition(params)
        self.actuator_outputs = [0.0] * 8
        self.power_fraction = 0.0
        self._transition_hold: TrajectorySetpoint | None = None
        self.vtol_state = VtolState.MC
        self.in_fixed_wing_flight = False

    def _publish_state(self) -> VtolState:
        state = self.transition.state
        self.vtol_state = state
        self.in_fixed_wing_flight = state == VtolState.FW
        return state

    @property
    def landing(self) -> LandingStatus:
        return self.mc.landing

    def request_transition(self, to_fixed_wing: bool, immediate: bool) -> None:
        self.transition.request(to_fixed_wing, immediate, airborne=not self.truth.on_ground)
        self._publish_state()

    def step(self, dt_s: float, armed: bool, setpoint: ControlSetpoint | None) -> None:
        self.mc.note_armed(dt_s, armed)
        if self.frame.tick_params(dt_s):
            self.rotors.refresh_params()
            self.fw.refresh_params()
            self.fw.mass_kg = self.frame.body.mass_kg
            self.fw.thrust_max_n = self.frame.pusher_max_n
        t = self.truth
        forward = rotate_ned_to_body(t.q_wxyz, t.velocity_ned_m_s)[0]
        # without a land detector (a model flown alone) only disarming counts as landed
        landed = self.landing.detector_attached and self.landing.landed
        self.transition.update(
            dt_s, t.airspeed_m_s, forward, disarmed_or_landed=not armed or landed
        )
        state = self._publish_state()
        if state not in (VtolState.TRANSITION_TO_FW, VtolState.TRANSITION_TO_MC):
            self._transition_hold = None

        lift = [0.0, 0.0, 0.0, 0.0]
        surfaces = SurfacesThrottle()
        if armed and setpoint is not None:
            setpoint = safe_setpoint(setpoint, t)
            if state == VtolState.FW:
                surfaces = self.fw.update(dt_s, t, setpoint)
                self.mc.reset()
            else:
                mc_setpoint = setpoint if state == VtolState.MC else self._transition_setpoint()
                lift = self._lift_rotors(dt_s, mc_setpoint, self.transition.mc_weight())
                if state == VtolState.MC:
                    # hovering: the rotors fly, the surfaces stay neutral
                    self.fw.reset()
                else:
                    surfaces = self._wings_level(dt_s)
                surfaces = surfaces._replace(throttle=self.transition.pusher_throttle)
        else:
            self.mc.reset()
            self.fw.reset()

        self.actuator_outputs = [
            *lift, surfaces.throttle, surfaces.aileron, surfaces.elevator, surfaces.rudder
        ]
        thrust_n, roll, pitch, yaw = self.rotors.advance(dt_s, lift)
        force, moment = self.frame.aero_and_pusher(dt_s, surfaces)
        self.power_fraction = (sum(self.rotors.lagged) + self.frame.pusher) / 5.0
        self.frame.integrate(
            dt_s,
            (force[0], force[1], force[2] - thrust_n),
            (moment[0] + roll, moment[1] + pitch, moment[2] + yaw),
        )

    def _lift_rotors(
        self, dt_s: float, setpoint: ControlSetpoint, weight: float = 1.0
    ) -> list[float]:
        cmd = self.mc.update(
            dt_s, self.truth, setpoint, self.rotors.hover_thrust(self.frame.body.mass_kg)
        )
        mixer = self.rotors.mixer
        outputs = mixer.mix(
            cmd.roll * weight, cmd.pitch * weight, cmd.yaw * weight, cmd.thrust * weight
        )
        self.mc.mixer_saturated = mixer.saturated
        return outputs

    def _transition_setpoint(self) -> TrajectorySetpoint:
        """During a transition the rotors hold height and heading and leave the horizontal
        speed to the pusher (front) or brake it (back)."""
        if self._transition_hold is None:
            t = self.truth
            front = self.transition.state == VtolState.TRANSITION_TO_FW
            self._transition_hold = TrajectorySetpoint(
                position_ned_m=[math.nan, math.nan, t.position_ned_m[2]],
                velocity_ned_m_s=[math.nan, math.nan, math.nan] if front else [0.0, 0.0, math.nan],
                acceleration_ned_m_s2=[0.0, 0.0, math.nan] if front else [math.nan] * 3,
                yaw_rad=yaw_from_quat(t.q_wxyz),
            )
        return self._transition_hold

    def _wings_level(self, dt_s: float) -> SurfacesThrottle:
        roll, pitch, _ = euler_from_quat(self.truth.q_wxyz)
        rates_sp = self.fw.attitude_rates(self.truth, roll, pitch, 0.0, 0.0)
        return self.fw.rate_control(dt_s, self.truth, rates_sp)

    def reset(self, position_ned_m: list[float], yaw_rad: float) -> None:
        self.frame.reset(position_ned_m, yaw_rad)
        self.rotors.stop()
        self.mc.reset()
        self.fw.reset()
        self.transition = VtolTransition(self.params)
        self._publish_state()
        self.actuator_outputs = [0.0] * 8
        self.power_fraction = 0.0
        self._transition_hold = None
