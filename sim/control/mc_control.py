"""The multicopter cascade after PX4's mc_pos_control, mc_att_control and mc_rate_control.

`sim.control.mc_pos_control` (position/velocity, 50 Hz) → `sim.control.mc_att_control` (attitude) →
`sim.control.mc_rate_control` (rates) → normalised torque and thrust for the mixer. Attitude and
rates run at every physics step; offboard attitude or rate setpoints enter the cascade
at their own level.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

from sim.control.mc_att_control import AttitudeControl
from sim.control.mc_pos_control import POSITION_LOOP_PERIOD_S, PositionControl
from sim.control.mc_rate_control import RateControl
from sim.control.mc_takeoff import TakeoffHandling, TakeoffState, want_takeoff
from sim.lib.numeric import clamp, finite_or, is_finite
from sim.lib.params import ParamReader, param_or
from sim.lib.topics import (
    AttitudeSetpoint,
    ControlSetpoint,
    LandingStatus,
    RatesSetpoint,
    TrajectorySetpoint,
    VehicleStateTruth,
)

# mc_pos_control's setpoint while not taken off: a large downward acceleration, no thrust
NO_THRUST_ACCELERATION_DOWN_M_S2 = 100.0

__all__ = ["AttitudeControl", "MulticopterControl", "PositionControl", "RateControl",
           "TorqueThrust"]


class TorqueThrust(NamedTuple):
    """Normalised commands for the mixer: roll/pitch/yaw in [-1, 1], thrust in [0, 1]."""

    roll: float
    pitch: float
    yaw: float
    thrust: float


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
        self.takeoff = TakeoffHandling()
        # shared with the land detector (the vehicle hands it over)
        self.landing = LandingStatus()
        self.refresh_params()

    def refresh_params(self) -> None:
        self.position.read_params_from(self.params)
        self.attitude.read_params_from(self.params)
        self.rates.read_params_from(self.params)
        self._spoolup_time_s = param_or(self.params, "COM_SPOOLUP_TIME", 1.0)
        self._takeoff_ramp_time_s = param_or(self.params, "MPC_TKO_RAMP_T", 3.0)
        self._since_params_s = 0.0

    def note_armed(self, dt_s: float, armed: bool) -> None:
        """Every physics step, whether the controllers run or not (the spool-up timer)."""
        self.takeoff.note_armed(dt_s, armed)
        if not armed:
            self.landing.thrust_setpoint = 0.0
            self.landing.takeoff_state = int(self.takeoff.state)

    def reset(self) -> None:
        self.position.reset()
        self.rates.reset()
        self._since_position_s = math.inf
        self.landing.thrust_setpoint = 0.0
        self.landing.velocity_setpoint_down_m_s = math.nan

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
            self._without_climb_rate_control(thrust)
        else:
            if isinstance(setpoint, AttitudeSetpoint):
                self._q_sp = setpoint.q_wxyz
                self._thrust = -setpoint.thrust_body[2]
                self._since_position_s = math.inf
                yawspeed = math.nan
                self.position.yaw_sp_rad = math.nan
                self._without_climb_rate_control(self._thrust)
            else:
                self._since_position_s += dt_s
                if self._since_position_s >= POSITION_LOOP_PERIOD_S - 1e-9:
                    # after a pause (other setpoint types, reset) integrate one period only
                    period = min(self._since_position_s, POSITION_LOOP_PERIOD_S)
                    self.position.hover_thrust = hover_thrust
                    tracked = self._takeoff_setpoint(period, truth, setpoint)
                    self._q_sp, self._thrust = self.position.update(
                        period, truth, tracked, False
                    )
                    self._publish_landing(hover_thrust, _wanted_descent_m_s(setpoint, truth))
                    self._since_position_s = 0.0
                yawspeed = self.position.yawspeed_sp_rad_s
            rates_sp = self.attitude.update(q, self._q_sp, yawspeed)
            thrust = self._thrust
        torque = self.rates.update(
            dt_s, truth.rates_body_rad_s, rates_sp, landed, self.mixer_saturated
        )
        return TorqueThrust(torque[0], torque[1], torque[2], clamp(thrust, 0.0, 1.0))

    def _takeoff_setpoint(
        self, dt_s: float, truth: VehicleStateTruth, sp: TrajectorySetpoint
    ) -> TrajectorySetpoint:
        """mc_pos_control's takeoff handling: no thrust before the ramp (and when flying
        with ground contact), then the ramped climb-speed limit."""
        climb_rate_controlled = is_finite(sp.position_ned_m[2]) or is_finite(
            sp.velocity_ned_m_s[2])
        takeoff = self.takeoff
        wanted = want_takeoff(sp.position_ned_m[2], sp.velocity_ned_m_s[2],
                              truth.position_ned_m[2])
        skip = not climb_rate_controlled or not self.landing.detector_attached
        takeoff.update_state(self.landing.landed, wanted, self._spoolup_time_s, skip=skip)
        self.landing.climb_rate_controlled = climb_rate_controlled
        climb_limit = takeoff.climb_limit_m_s(
            dt_s, finite_or(sp.max_speed_up_m_s, self.position.vel_max_up_m_s),
            self._takeoff_ramp_time_s, self.position.gain_vel_p[2])
        not_taken_off = takeoff.state < TakeoffState.RAMPUP
        ground_contact = takeoff.state >= TakeoffState.FLIGHT and self.landing.ground_contact
        if not skip and (not_taken_off or ground_contact):
            self.position.vel_int = [0.0, 0.0, 0.0]
            return TrajectorySetpoint(
                acceleration_ned_m_s2=[0.0, 0.0, NO_THRUST_ACCELERATION_DOWN_M_S2])
        if takeoff.state == TakeoffState.RAMPUP and is_finite(sp.velocity_ned_m_s[2]):
            acceleration = [*sp.acceleration_ned_m_s2[:2], math.nan]
            sp = dataclasses.replace(sp, acceleration_ned_m_s2=acceleration)
        if takeoff.state < TakeoffState.FLIGHT:
            sp = dataclasses.replace(sp, max_speed_up_m_s=climb_limit)
        return sp

    def _publish_landing(self, hover_thrust: float, descent_m_s: float) -> None:
        self.landing.thrust_setpoint = self._thrust
        self.landing.velocity_setpoint_down_m_s = descent_m_s
        self.landing.hover_thrust = hover_thrust
        self.landing.takeoff_state = int(self.takeoff.state)

    def _without_climb_rate_control(self, thrust: float) -> None:
        """Attitude or rate setpoints: no takeoff handling, thrust as given."""
        self.takeoff.update_state(self.landing.landed, False, self._spoolup_time_s, skip=True)
        self.landing.climb_rate_controlled = False
        self.landing.thrust_setpoint = thrust
        self.landing.velocity_setpoint_down_m_s = math.nan
        self.landing.takeoff_state = int(self.takeoff.state)


def _wanted_descent_m_s(sp: TrajectorySetpoint, truth: VehicleStateTruth) -> float:
    """The vertical speed the mode asks for (the flight task's trajectory setpoint), before
    the takeoff handling replaces it: the velocity given, or the position error times
    MPC_Z_P's default gain, within the setpoint's descent limit."""
    down = sp.velocity_ned_m_s[2]
    if is_finite(sp.position_ned_m[2]):
        from_position = sp.position_ned_m[2] - truth.position_ned_m[2]
        down = from_position if not is_finite(down) else down + from_position
    if is_finite(down) and is_finite(sp.max_speed_down_m_s):
        down = min(down, sp.max_speed_down_m_s)
    return down
