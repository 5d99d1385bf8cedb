"""The landing descent shared by Land, Return's last phase and the stick-less manual modes,
after PX4's navigator land and the position controller's landing speed."""

from __future__ import annotations

from typing import Protocol

from sim.commander import Commander
from sim.params import ParamReader
from sim.topics import TrajectorySetpoint, VehicleStateTruth, VtolState

# Setpoint depth below ground used while landing, so the controller keeps descending
# at the land speed until the ground stops it.
LAND_TARGET_BELOW_GROUND_M = 1.0


class VtolAirframe(Protocol):
    """What the navigator needs from the airframe model (a subset of AirframeModel)."""

    is_vtol: bool
    in_fixed_wing_flight: bool
    vtol_state: VtolState

    def request_transition(self, to_fixed_wing: bool, immediate: bool) -> None: ...


class Land:
    def __init__(
        self,
        params: ParamReader,
        commander: Commander,
        airframe: VtolAirframe,
        *,
        ground_vehicle: bool = False,
    ) -> None:
        self._params = params
        self._commander = commander
        self._airframe = airframe
        self._ground_vehicle = ground_vehicle

    def speed_m_s(self, altitude_m: float) -> float:
        """PX4's descent speed over ground: fast above MPC_LAND_ALT1, slow below ALT2."""
        slow = self._params.get("MPC_LAND_SPEED")
        fast = self._params.get("MPC_Z_VEL_MAX_DN")
        alt1 = self._params.get("MPC_LAND_ALT1")
        alt2 = self._params.get("MPC_LAND_ALT2")
        if altitude_m >= alt1:
            return fast
        if altitude_m <= alt2 or alt1 <= alt2:
            return slow
        return slow + (fast - slow) * (altitude_m - alt2) / (alt1 - alt2)

    def setpoint(
        self, truth: VehicleStateTruth, xy: list[float], yaw_rad: float
    ) -> TrajectorySetpoint | None:
        """Land at xy: a VTOL goes back to multicopter first; None once landed."""
        if self._airframe.is_vtol and self._airframe.in_fixed_wing_flight:
            self._airframe.request_transition(to_fixed_wing=False, immediate=False)
        if self._commander.landed:
            return None
        return self.descend(xy, self.speed_m_s(-truth.position_ned_m[2]), yaw_rad)

    def descend(self, xy: list[float], speed_m_s: float, yaw_rad: float) -> TrajectorySetpoint:
        if self._ground_vehicle:  # a rover "lands" by stopping where it is
            return TrajectorySetpoint(position_ned_m=[xy[0], xy[1], 0.0])
        return TrajectorySetpoint(
            position_ned_m=[xy[0], xy[1], LAND_TARGET_BELOW_GROUND_M],
            yaw_rad=yaw_rad,
            max_speed_down_m_s=speed_m_s,
        )
