"""What every navigator mode works with, after PX4's MissionBlock: parameters, the
commander, the airframe, the announcer, and the landing descent that Land, Return's last
phase and the stick-less manual modes share."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from sim.flight.commander import Commander
from sim.flight.commander_failsafe import Announce
from sim.lib.params import ParamReader
from sim.lib.topics import TrajectorySetpoint, VehicleStateTruth, VtolState

# Setpoint depth below ground used while landing, so the controller keeps descending
# at the land speed until the ground stops it.
LAND_TARGET_BELOW_GROUND_M = 1.0


class VtolAirframe(Protocol):
    """What the navigator needs from the airframe model (a subset of AirframeModel)."""

    is_vtol: bool
    in_fixed_wing_flight: bool
    vtol_state: VtolState

    def request_transition(self, to_fixed_wing: bool, immediate: bool) -> None: ...


@dataclass
class MissionBlock:
    params: ParamReader
    commander: Commander
    airframe: VtolAirframe
    announce: Announce
    ground_vehicle: bool = False

    def land_speed_m_s(self, altitude_m: float) -> float:
        """FlightTaskAuto's landing descent: MPC_Z_VEL_MAX_DN above MPC_LAND_ALT1, blended
        down to MPC_LAND_SPEED at MPC_LAND_ALT2, and MPC_LAND_CRWL once the range finder
        reads less than MPC_LAND_ALT3."""
        slow = self.params.get("MPC_LAND_SPEED")
        fast = self.params.get("MPC_Z_VEL_MAX_DN")
        alt1 = self.params.get("MPC_LAND_ALT1")
        alt2 = self.params.get("MPC_LAND_ALT2")
        if 0.0 <= altitude_m <= self.params.get("MPC_LAND_ALT3"):
            return self.params.get("MPC_LAND_CRWL")
        if altitude_m >= alt1:
            return fast
        if altitude_m <= alt2 or alt1 <= alt2:
            return slow
        return slow + (fast - slow) * (altitude_m - alt2) / (alt1 - alt2)

    def land_setpoint(
        self, truth: VehicleStateTruth, xy: list[float], yaw_rad: float
    ) -> TrajectorySetpoint | None:
        """Land at xy: a VTOL goes back to multicopter first; None once landed."""
        if self.airframe.is_vtol and self.airframe.in_fixed_wing_flight:
            self.airframe.request_transition(to_fixed_wing=False, immediate=False)
        if self.commander.landed:
            return None
        return self.descend_setpoint(xy, self.land_speed_m_s(-truth.position_ned_m[2]), yaw_rad)

    def descend_setpoint(
        self, xy: list[float], speed_m_s: float, yaw_rad: float
    ) -> TrajectorySetpoint:
        if self.ground_vehicle:  # a rover "lands" by stopping where it is
            return TrajectorySetpoint(position_ned_m=[xy[0], xy[1], 0.0])
        return TrajectorySetpoint(
            position_ned_m=[xy[0], xy[1], LAND_TARGET_BELOW_GROUND_M],
            yaw_rad=yaw_rad,
            max_speed_down_m_s=speed_m_s,
        )
