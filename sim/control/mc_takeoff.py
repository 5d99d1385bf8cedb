"""The multicopter takeoff after PX4's mc_pos_control TakeoffHandling.

Armed, the motors spool up for COM_SPOOLUP_TIME before the vehicle may take off. A takeoff
is wanted once the position setpoint is 0.2 m above the vehicle or the velocity setpoint
climbs faster than 0.3 m/s (FlightTask::_checkTakeoff). The climb speed limit then ramps
over MPC_TKO_RAMP_T from the speed at which the velocity controller asks for no thrust at
all (-g / MPC_Z_VEL_P_ACC, a descent) up to the mode's climb speed, so thrust rises
smoothly from nothing. Until the ramp starts, and while flying with ground contact, the
controller asks for no thrust and keeps its integrators at zero.
"""

from __future__ import annotations

from enum import IntEnum

from sim.physics.rigid_body import GRAVITY_M_S2

# FlightTask::_checkTakeoff: the setpoint must be this far above the vehicle
TAKEOFF_MIN_ALTITUDE_M = 0.2
TAKEOFF_MIN_CLIMB_M_S = 0.3


class TakeoffState(IntEnum):
    """takeoff_status.takeoff_state."""

    DISARMED = 1
    SPOOLUP = 2
    READY_FOR_TAKEOFF = 3
    RAMPUP = 4
    FLIGHT = 5


class TakeoffHandling:
    def __init__(self) -> None:
        self.state = TakeoffState.DISARMED
        self._armed_s = 0.0
        self._ramp_progress = 0.0

    def note_armed(self, dt_s: float, armed: bool) -> None:
        """Every physics step: the spool-up counts from arming, whatever the mode."""
        self._armed_s = self._armed_s + dt_s if armed else 0.0
        if not armed:
            self.state = TakeoffState.DISARMED

    def update_state(
        self, landed: bool, want_takeoff: bool, spoolup_time_s: float, skip: bool
    ) -> None:
        """TakeoffHandling::updateTakeoffState for an armed vehicle."""
        if self.state == TakeoffState.DISARMED:
            self.state = TakeoffState.SPOOLUP
        if self.state == TakeoffState.SPOOLUP and self._armed_s >= spoolup_time_s:
            self.state = TakeoffState.READY_FOR_TAKEOFF
        if self.state == TakeoffState.READY_FOR_TAKEOFF and want_takeoff:
            self.state = TakeoffState.RAMPUP
            self._ramp_progress = 0.0
        if self.state == TakeoffState.RAMPUP and self._ramp_progress >= 1.0:
            self.state = TakeoffState.FLIGHT
        if self.state == TakeoffState.FLIGHT and landed:
            self.state = TakeoffState.READY_FOR_TAKEOFF
        if skip:
            self.state = TakeoffState.FLIGHT

    def climb_limit_m_s(
        self, dt_s: float, climb_speed_m_s: float, ramp_time_s: float, vel_p_gain_z: float
    ) -> float:
        """TakeoffHandling::updateRamp: the upward speed limit now (negative: must sink)."""
        initial = -GRAVITY_M_S2 / max(vel_p_gain_z, 0.01)
        if self.state < TakeoffState.RAMPUP:
            return initial
        if self.state == TakeoffState.RAMPUP:
            if ramp_time_s > dt_s:
                self._ramp_progress += dt_s / ramp_time_s
            else:
                self._ramp_progress = 1.0
            if self._ramp_progress < 1.0:
                return initial + self._ramp_progress * (climb_speed_m_s - initial)
        return climb_speed_m_s


def want_takeoff(setpoint_down_m: float, setpoint_vel_down_m_s: float, down_m: float) -> bool:
    """FlightTask::_checkTakeoff (NaN setpoints trigger nothing)."""
    by_position = setpoint_down_m < down_m - TAKEOFF_MIN_ALTITUDE_M
    by_velocity = setpoint_vel_down_m_s < -TAKEOFF_MIN_CLIMB_M_S
    return by_position or by_velocity
