"""The multicopter cascade after PX4's mc_pos_control, mc_att_control and mc_rate_control.

`sim.control.mc_pos_control` (position/velocity, 50 Hz) → `sim.control.mc_att_control` (attitude) →
`sim.control.mc_rate_control` (rates) → normalised torque and thrust for the mixer. Attitude and
rates run at every physics step; offboard attitude or rate setpoints enter the cascade
at their own level.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from sim.control.mc_att_control import AttitudeControl
from sim.control.mc_pos_control import POSITION_LOOP_PERIOD_S, PositionControl
from sim.control.mc_rate_control import RateControl
from sim.lib.numeric import clamp
from sim.lib.params import ParamReader
from sim.lib.topics import AttitudeSetpoint, ControlSetpoint, RatesSetpoint, VehicleStateTruth

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
