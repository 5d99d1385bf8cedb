"""Return to launch, after PX4's rtl_direct: climb, return, descend, loiter, land.

A VTOL in fixed-wing flight flies an approach to home and transitions back to
multicopter before landing; a plane lands where it loiters.
"""

from __future__ import annotations

import math
from enum import Enum

from sim.flight.auto_trajectory import StraightMove
from sim.flight.commander_failsafe import MAV_SEVERITY_INFO
from sim.flight.mission_block import MissionBlock
from sim.lib.quat import yaw_from_quat
from sim.lib.topics import TrajectorySetpoint, VehicleStateTruth, VtolState

ALTITUDE_REACHED_M = 0.5
MC_POSITION_REACHED_M = 1.0
# A fixed wing counts as arrived anywhere on (or near) its loiter circle around the point.
FW_LOITER_REACHED_FACTOR = 1.5


class RtlPhase(Enum):
    """PX4 rtl_direct's RTLState."""

    CLIMBING = "climbing"
    MOVE_TO_LOITER = "move_to_loiter"
    LOITER_DOWN = "loiter_down"
    LOITER_HOLD = "loiter_hold"
    MOVE_TO_LAND = "move_to_land"
    TRANSITION_TO_MC = "transition_to_mc"
    MOVE_TO_LAND_HOVER = "move_to_land_hover"
    LAND = "land"
    IDLE = "idle"


class RtlDirect:
    def __init__(self, block: MissionBlock) -> None:
        self._block = block
        self.phase = RtlPhase.IDLE
        self.phases_seen: list[RtlPhase] = []
        self._return_down_m = 0.0
        self._descend_down_m = 0.0
        self._phase_started_s = 0.0
        self._climb_xy = [0.0, 0.0]
        self._land_xy = [0.0, 0.0]
        self._yaw_rad = math.nan
        self._move = StraightMove(block.params)
        self._last_s = 0.0

    def start(self, now_s: float, truth: VehicleStateTruth) -> None:
        self.phases_seen = []
        self._move.reset()
        self._last_s = now_s
        home = self._block.commander.home
        home_down = home.position_ned_m[2]
        down = truth.position_ned_m[2]
        far = self._home_distance_m(truth) > self._block.params.get("RTL_MIN_DIST")
        far = far and not self._block.ground_vehicle
        return_down = home_down - self._block.params.get("RTL_RETURN_ALT")
        self._return_down_m = min(return_down, down) if far else down
        self._descend_down_m = max(
            self._return_down_m, home_down - self._block.params.get("RTL_DESCEND_ALT")
        )
        self._yaw_rad = yaw_from_quat(truth.q_wxyz)
        self._land_xy = [home.position_ned_m[0], home.position_ned_m[1]]
        self._climb_xy = [truth.position_ned_m[0], truth.position_ned_m[1]]
        self._announce_start()
        if self._block.commander.landed:
            self._enter_phase(RtlPhase.IDLE, now_s)
        elif down > self._return_down_m + ALTITUDE_REACHED_M:
            self._enter_phase(RtlPhase.CLIMBING, now_s)
        else:
            self._enter_phase(RtlPhase.MOVE_TO_LOITER, now_s)

    def setpoint(self, now_s: float, truth: VehicleStateTruth) -> TrajectorySetpoint | None:
        phase = self.phase
        nxt = self._next_phase(phase, now_s, truth)
        while nxt is not None:
            self._enter_phase(nxt, now_s)
            phase = nxt
            nxt = self._next_phase(phase, now_s, truth)
        dt_s, self._last_s = now_s - self._last_s, now_s
        return self._smoothed(self._phase_setpoint(phase, truth), dt_s, truth)

    def _smoothed(
        self, sp: TrajectorySetpoint | None, dt_s: float, truth: VehicleStateTruth
    ) -> TrajectorySetpoint | None:
        """A multicopter flies the climb, the return and the descent as PX4's auto flight
        task does: along a jerk-limited straight line (`sim.flight.auto_trajectory`)."""
        multicopter = not (self._block.ground_vehicle or self._block.airframe.in_fixed_wing_flight
                           or self.phase in (RtlPhase.LAND, RtlPhase.IDLE))
        if sp is None or not multicopter or not all(
                math.isfinite(x) for x in sp.position_ned_m):
            self._move.reset()
            return sp
        xy_speed = sp.max_speed_xy_m_s
        if not math.isfinite(xy_speed):
            xy_speed = self._block.params.get("MPC_XY_CRUISE")
        position, velocity = self._move.setpoint(
            dt_s, truth.position_ned_m, sp.position_ned_m, xy_speed)
        return TrajectorySetpoint(
            position_ned_m=position, velocity_ned_m_s=velocity, yaw_rad=sp.yaw_rad,
            max_speed_xy_m_s=sp.max_speed_xy_m_s)

    def _home_distance_m(self, truth: VehicleStateTruth) -> float:
        home = self._block.commander.home.position_ned_m
        return math.hypot(truth.position_ned_m[0] - home[0], truth.position_ned_m[1] - home[1])

    def _enter_phase(self, phase: RtlPhase, now_s: float) -> None:
        self.phase = phase
        self.phases_seen.append(phase)
        self._phase_started_s = now_s
        # PX4's rtl_direct says only where it lands; the start is said on activation
        if phase == RtlPhase.LAND:
            self._block.announce(MAV_SEVERITY_INFO, "RTL: land at destination")

    def _announce_start(self) -> None:
        """RtlDirect::on_activation: the return altitude, AMSL and above the destination
        (home), rounded up as PX4 does."""
        home_down = self._block.commander.home.position_ned_m[2]
        above = home_down - self._return_down_m
        above_m = math.ceil(round(above, 3))
        amsl_m = math.ceil(round(self._block.commander.home.alt_m + above, 3))
        self._block.announce(
            MAV_SEVERITY_INFO, f"RTL: start return at {amsl_m} m ({above_m} m above destination)"
        )

    def _next_phase(
        self, phase: RtlPhase, now_s: float, truth: VehicleStateTruth
    ) -> RtlPhase | None:
        down = truth.position_ned_m[2]
        fixed_wing = self._block.airframe.in_fixed_wing_flight
        if phase == RtlPhase.CLIMBING:
            reached = down <= self._return_down_m + ALTITUDE_REACHED_M
            return RtlPhase.MOVE_TO_LOITER if reached else None
        if phase == RtlPhase.MOVE_TO_LOITER:
            reached = self._home_distance_m(truth) <= self._reach_radius_m(fixed_wing)
            return RtlPhase.LOITER_DOWN if reached else None
        if phase == RtlPhase.LOITER_DOWN:
            reached = down >= self._descend_down_m - ALTITUDE_REACHED_M
            return RtlPhase.LOITER_HOLD if reached else None
        if phase == RtlPhase.LOITER_HOLD:
            delay = self._block.params.get("RTL_LAND_DELAY")
            if delay < 0 or now_s - self._phase_started_s < delay:
                return None
            # rtl_direct: only a VTOL in fixed-wing flight flies an approach and transitions;
            # a plane goes on to land where it loiters.
            vtol_in_fw = fixed_wing and self._block.airframe.is_vtol
            return RtlPhase.MOVE_TO_LAND if vtol_in_fw else RtlPhase.MOVE_TO_LAND_HOVER
        if phase == RtlPhase.MOVE_TO_LAND:
            near = self._home_distance_m(truth) <= self._back_transition_distance_m(truth)
            return RtlPhase.TRANSITION_TO_MC if near or not fixed_wing else None
        if phase == RtlPhase.TRANSITION_TO_MC:
            in_mc = self._block.airframe.vtol_state == VtolState.MC
            return RtlPhase.MOVE_TO_LAND_HOVER if in_mc else None
        if phase == RtlPhase.MOVE_TO_LAND_HOVER:
            near = self._home_distance_m(truth) <= self._reach_radius_m(fixed_wing)
            return RtlPhase.LAND if near else None
        if phase == RtlPhase.LAND:
            if self._block.ground_vehicle:
                return RtlPhase.IDLE  # arrived: a rover stops and stays armed
            return RtlPhase.IDLE if self._block.commander.landed else None
        return None

    def _phase_setpoint(
        self, phase: RtlPhase, truth: VehicleStateTruth
    ) -> TrajectorySetpoint | None:
        home = self._block.commander.home
        if phase == RtlPhase.IDLE:
            return None
        if phase == RtlPhase.LAND:
            return self._block.land_setpoint(truth, self._land_xy, self._yaw_rad)
        if phase == RtlPhase.CLIMBING:
            north, east = self._climb_xy
            return TrajectorySetpoint(
                position_ned_m=[north, east, self._return_down_m], yaw_rad=self._yaw_rad
            )
        if phase == RtlPhase.MOVE_TO_LAND and self._block.airframe.in_fixed_wing_flight:
            return self._approach_home(truth)
        if phase == RtlPhase.TRANSITION_TO_MC:
            self._block.airframe.request_transition(to_fixed_wing=False, immediate=False)
        down = self._descend_down_m
        if phase == RtlPhase.MOVE_TO_LOITER:
            down = self._return_down_m
        return TrajectorySetpoint(
            position_ned_m=[home.position_ned_m[0], home.position_ned_m[1], down],
            yaw_rad=self._return_yaw_rad(truth),
            max_speed_xy_m_s=self._block.params.get("MPC_XY_CRUISE"),
        )

    def _reach_radius_m(self, fixed_wing: bool) -> float:
        """A multicopter arrives over a point; a fixed wing once on its loiter circle."""
        if fixed_wing:
            return self._block.params.get("NAV_LOITER_RAD") * FW_LOITER_REACHED_FACTOR
        return MC_POSITION_REACHED_M

    def _back_transition_distance_m(self, truth: VehicleStateTruth) -> float:
        """PX4's acceptance radius of a waypoint with a back transition: the distance the
        VTOL needs to stop from its ground speed at VT_B_DEC_MSS."""
        velocity = truth.velocity_ned_m_s
        speed = math.hypot(velocity[0], velocity[1])
        deceleration = self._block.params.get("VT_B_DEC_MSS")
        if deceleration <= 0.0:
            return MC_POSITION_REACHED_M
        return max(speed * speed / (2.0 * deceleration), MC_POSITION_REACHED_M)

    def _approach_home(self, truth: VehicleStateTruth) -> TrajectorySetpoint:
        """Fixed-wing flight straight at home at the descend altitude (a course, so the
        wing does not settle on a loiter circle around it)."""
        home = self._block.commander.home.position_ned_m
        bearing = math.atan2(
            home[1] - truth.position_ned_m[1], home[0] - truth.position_ned_m[0]
        )
        speed = self._block.params.get("FW_AIRSPD_TRIM")
        return TrajectorySetpoint(
            position_ned_m=[math.nan, math.nan, self._descend_down_m],
            velocity_ned_m_s=[speed * math.cos(bearing), speed * math.sin(bearing), math.nan],
        )

    def _return_yaw_rad(self, truth: VehicleStateTruth) -> float:
        """Towards home while far, home's yaw within RTL_MIN_DIST (seed 004)."""
        home = self._block.commander.home
        if self._home_distance_m(truth) < self._block.params.get("RTL_MIN_DIST"):
            return home.yaw_rad
        return math.atan2(
            home.position_ned_m[1] - truth.position_ned_m[1],
            home.position_ned_m[0] - truth.position_ned_m[0],
        )
