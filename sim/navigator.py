"""Autonomous modes of the simulated vehicle, after PX4's navigator.

Takeoff, Hold (loiter), Land, Return (rtl_direct's phases) and DO_REPOSITION, plus
the stick-less behaviour of the manual modes. Each mode turns into a
TrajectorySetpoint for the airframe's controllers; None means motors idle.
"""

from __future__ import annotations

import math
from enum import Enum
from typing import Protocol

from sim import modes
from sim.commander import MAV_SEVERITY_INFO, Announce, Commander
from sim.modes import Px4Mode
from sim.params import ParamReader
from sim.topics import TrajectorySetpoint, VehicleStateTruth, VtolState

# PX4 ends the takeoff and switches to Hold slightly below the target altitude.
TAKEOFF_DONE_FRACTION = 0.9
# Smallest share of MPC_TKO_SPEED at the start of the takeoff ramp, so the climb starts.
TAKEOFF_RAMP_FLOOR = 0.1
# A manual mode without stick input (no RC attached) lets the vehicle sink slowly.
NO_RC_DESCENT_SPEED_M_S = 0.8
# Setpoint depth below ground used while landing, so the controller keeps descending
# at the land speed until the ground stops it.
LAND_TARGET_BELOW_GROUND_M = 1.0
ALTITUDE_REACHED_M = 0.5
MC_POSITION_REACHED_M = 1.0
# A fixed wing counts as arrived anywhere on (or near) its loiter circle around the point.
FW_LOITER_REACHED_FACTOR = 1.5

_STICKLESS_MODES = frozenset(
    {modes.POSCTL, modes.ALTCTL, modes.STABILIZED, modes.MANUAL, modes.ACRO}
)
_TAKEOFF_MODES = frozenset({modes.AUTO_TAKEOFF, modes.AUTO_VTOL_TAKEOFF})


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


class VtolAirframe(Protocol):
    """What the navigator needs from the airframe model (a subset of AirframeModel)."""

    is_vtol: bool
    in_fixed_wing_flight: bool
    vtol_state: VtolState

    def request_transition(self, to_fixed_wing: bool, immediate: bool) -> None: ...


def yaw_of(truth: VehicleStateTruth) -> float:
    w, x, y, z = truth.q_wxyz
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class Navigator:
    def __init__(
        self,
        params: ParamReader,
        commander: Commander,
        airframe: VtolAirframe,
        announce: Announce,
        *,
        fixed_wing_only: bool = False,
        ground_vehicle: bool = False,
    ) -> None:
        self._params = params
        self._commander = commander
        self._airframe = airframe
        self._announce = announce
        self._fixed_wing_only = fixed_wing_only
        self._ground_vehicle = ground_vehicle
        self._active: Px4Mode | None = None
        self._hold_target: list[float] = [0.0, 0.0, 0.0]
        self._hold_yaw_rad = math.nan
        self._hold_speed_m_s = math.nan
        self._pending_hold: tuple[list[float], float, float] | None = None
        self._takeoff_alt_amsl_m = math.nan
        self._takeoff_target: list[float] | None = None
        self._takeoff_start_down_m = 0.0
        self._takeoff_started_s = 0.0
        self._land_xy: list[float] = [0.0, 0.0]
        self.rtl_phase = RtlPhase.IDLE
        self.rtl_phases_seen: list[RtlPhase] = []
        self._rtl_return_down_m = 0.0
        self._rtl_descend_down_m = 0.0
        self._rtl_phase_started_s = 0.0
        self._rtl_climb_xy = [0.0, 0.0]

    # -- requests ----------------------------------------------------------------------

    def request_takeoff(self, alt_amsl_m: float) -> None:
        """NAV_TAKEOFF param7 (NaN = current altitude + MIS_TAKEOFF_ALT)."""
        self._takeoff_alt_amsl_m = alt_amsl_m
        self._takeoff_target = None
        self._active = None

    def request_reposition(
        self, target_ned_m: list[float], yaw_rad: float, speed_m_s: float
    ) -> None:
        """DO_REPOSITION: fly there in Hold; NaN components were filled by the caller."""
        self._pending_hold = (list(target_ned_m), yaw_rad, speed_m_s)
        self._active = None

    @property
    def takeoff_target_ned_m(self) -> list[float] | None:
        return self._takeoff_target

    @property
    def hold_target_ned_m(self) -> list[float]:
        return self._hold_target

    # -- per step ----------------------------------------------------------------------

    def setpoint(
        self, now_s: float, truth: VehicleStateTruth, origin_alt_m: float
    ) -> TrajectorySetpoint | None:
        mode = self._commander.nav_mode
        if mode != self._active:
            self._activate(mode, now_s, truth)
        if not self._commander.armed:
            return None
        if mode in _TAKEOFF_MODES:
            return self._takeoff(now_s, truth, origin_alt_m)
        if mode == modes.AUTO_LOITER:
            return self._hold(truth)
        if mode == modes.AUTO_LAND:
            return self._land(truth, self._land_xy)
        if mode == modes.AUTO_RTL:
            return self._rtl(now_s, truth)
        if mode in _STICKLESS_MODES:
            return self._stickless(truth)
        return None

    def _activate(self, mode: Px4Mode, now_s: float, truth: VehicleStateTruth) -> None:
        self._active = mode
        position = truth.position_ned_m
        if mode == modes.AUTO_LOITER:
            if self._pending_hold is not None:
                self._hold_target, self._hold_yaw_rad, self._hold_speed_m_s = self._pending_hold
                self._pending_hold = None
            else:
                self._hold_target = list(position)
                self._hold_yaw_rad = yaw_of(truth)
                self._hold_speed_m_s = math.nan
        elif mode in (modes.AUTO_LAND, *_STICKLESS_MODES):
            self._land_xy = [position[0], position[1]]
            self._hold_yaw_rad = yaw_of(truth)
        elif mode == modes.AUTO_RTL:
            self._start_rtl(now_s, truth)
        elif mode in _TAKEOFF_MODES:
            # The target is fixed at the first armed step, from where the vehicle is then.
            self._takeoff_target = None

    # -- takeoff -----------------------------------------------------------------------

    def _takeoff(
        self, now_s: float, truth: VehicleStateTruth, origin_alt_m: float
    ) -> TrajectorySetpoint:
        if self._takeoff_target is None:
            self._takeoff_target = self._takeoff_target_from(truth, origin_alt_m)
            self._takeoff_start_down_m = truth.position_ned_m[2]
            self._takeoff_started_s = now_s
            self._hold_yaw_rad = yaw_of(truth)
        target = self._takeoff_target
        climb_m = self._takeoff_start_down_m - target[2]
        climbed_m = self._takeoff_start_down_m - truth.position_ned_m[2]
        if climb_m <= 0.0 or climbed_m >= TAKEOFF_DONE_FRACTION * climb_m:
            self._announce(MAV_SEVERITY_INFO, "Takeoff complete, holding position")
            self._pending_hold = (list(target), self._hold_yaw_rad, math.nan)
            self._takeoff_alt_amsl_m = math.nan
            self._commander.switch_mode(modes.AUTO_LOITER)
        # PX4 ramps the climb speed up over MPC_TKO_RAMP_T for a smooth lift-off.
        ramp_s = self._params.get("MPC_TKO_RAMP_T")
        ramp = min((now_s - self._takeoff_started_s) / ramp_s, 1.0) if ramp_s > 0 else 1.0
        return TrajectorySetpoint(
            position_ned_m=list(target),
            yaw_rad=self._hold_yaw_rad,
            max_speed_up_m_s=self._params.get("MPC_TKO_SPEED") * max(ramp, TAKEOFF_RAMP_FLOOR),
        )

    def _takeoff_target_from(self, truth: VehicleStateTruth, origin_alt_m: float) -> list[float]:
        north, east, down = truth.position_ned_m
        if math.isfinite(self._takeoff_alt_amsl_m):
            target_down = origin_alt_m - self._takeoff_alt_amsl_m
        else:
            home_down = self._commander.home.position_ned_m[2]
            base_down = min(down, home_down) if self._commander.home.valid else down
            target_down = base_down - self._params.get("MIS_TAKEOFF_ALT")
        if self._fixed_wing_only:
            yaw = yaw_of(truth)
            ahead_m = self._params.get("NAV_LOITER_RAD") * 2.0
            return [north + ahead_m * math.cos(yaw), east + ahead_m * math.sin(yaw), target_down]
        return [north, east, target_down]

    # -- hold, land, stick-less --------------------------------------------------------

    def _hold(self, truth: VehicleStateTruth) -> TrajectorySetpoint | None:
        if self._commander.landed and not self._commander.took_off_since_arming:
            return None
        return TrajectorySetpoint(
            position_ned_m=list(self._hold_target),
            yaw_rad=self._hold_yaw_rad,
            max_speed_xy_m_s=self._hold_speed_m_s,
        )

    def land_speed_m_s(self, altitude_m: float) -> float:
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

    def _land(self, truth: VehicleStateTruth, xy: list[float]) -> TrajectorySetpoint | None:
        if self._airframe.is_vtol and self._airframe.in_fixed_wing_flight:
            self._airframe.request_transition(to_fixed_wing=False, immediate=False)
        if self._commander.landed:
            return None
        return self._descend(xy, self.land_speed_m_s(-truth.position_ned_m[2]))

    def _stickless(self, truth: VehicleStateTruth) -> TrajectorySetpoint | None:
        if self._commander.landed:
            return None
        return self._descend(self._land_xy, NO_RC_DESCENT_SPEED_M_S)

    def _descend(self, xy: list[float], speed_m_s: float) -> TrajectorySetpoint:
        if self._ground_vehicle:  # a rover "lands" by stopping where it is
            return TrajectorySetpoint(position_ned_m=[xy[0], xy[1], 0.0])
        return TrajectorySetpoint(
            position_ned_m=[xy[0], xy[1], LAND_TARGET_BELOW_GROUND_M],
            yaw_rad=self._hold_yaw_rad,
            max_speed_down_m_s=speed_m_s,
        )

    # -- return to launch --------------------------------------------------------------

    def _start_rtl(self, now_s: float, truth: VehicleStateTruth) -> None:
        self.rtl_phases_seen = []
        home = self._commander.home
        home_down = home.position_ned_m[2]
        down = truth.position_ned_m[2]
        far = self._home_distance_m(truth) > self._params.get("RTL_MIN_DIST")
        far = far and not self._ground_vehicle
        return_down = home_down - self._params.get("RTL_RETURN_ALT")
        self._rtl_return_down_m = min(return_down, down) if far else down
        self._rtl_descend_down_m = max(
            self._rtl_return_down_m, home_down - self._params.get("RTL_DESCEND_ALT")
        )
        self._hold_yaw_rad = yaw_of(truth)
        self._land_xy = [home.position_ned_m[0], home.position_ned_m[1]]
        self._rtl_climb_xy = [truth.position_ned_m[0], truth.position_ned_m[1]]
        if self._commander.landed:
            self._enter_rtl_phase(RtlPhase.IDLE, now_s)
        elif down > self._rtl_return_down_m + ALTITUDE_REACHED_M:
            self._enter_rtl_phase(RtlPhase.CLIMBING, now_s)
        else:
            self._enter_rtl_phase(RtlPhase.MOVE_TO_LOITER, now_s)

    def _home_distance_m(self, truth: VehicleStateTruth) -> float:
        home = self._commander.home.position_ned_m
        return math.hypot(truth.position_ned_m[0] - home[0], truth.position_ned_m[1] - home[1])

    def _enter_rtl_phase(self, phase: RtlPhase, now_s: float) -> None:
        self.rtl_phase = phase
        self.rtl_phases_seen.append(phase)
        self._rtl_phase_started_s = now_s
        text = self._rtl_phase_text(phase)
        if text:
            self._announce(MAV_SEVERITY_INFO, text)

    def _rtl_phase_text(self, phase: RtlPhase) -> str:
        home_down = self._commander.home.position_ned_m[2]
        home_alt = self._commander.home.alt_m

        def altitude(down: float) -> str:
            return f"{home_alt + home_down - down:.0f} m ({home_down - down:.0f} m above home)"

        texts = {
            RtlPhase.CLIMBING: f"RTL: climb to {altitude(self._rtl_return_down_m)}",
            RtlPhase.MOVE_TO_LOITER: f"RTL: return at {altitude(self._rtl_return_down_m)}",
            RtlPhase.LOITER_DOWN: f"RTL: descend to {altitude(self._rtl_descend_down_m)}",
            RtlPhase.LOITER_HOLD: f"RTL: loiter {self._params.get('RTL_LAND_DELAY'):.1f}s",
            RtlPhase.MOVE_TO_LAND: "RTL: move to land approach",
            RtlPhase.TRANSITION_TO_MC: "RTL: transition to multicopter",
            RtlPhase.MOVE_TO_LAND_HOVER: "RTL: move to land position",
            RtlPhase.LAND: "RTL: land at home",
            RtlPhase.IDLE: "RTL: landed",
        }
        return texts[phase]

    def _rtl(self, now_s: float, truth: VehicleStateTruth) -> TrajectorySetpoint | None:
        phase = self.rtl_phase
        nxt = self._rtl_next_phase(phase, now_s, truth)
        while nxt is not None:
            self._enter_rtl_phase(nxt, now_s)
            phase = nxt
            nxt = self._rtl_next_phase(phase, now_s, truth)
        return self._rtl_setpoint(phase, truth)

    def _rtl_next_phase(
        self, phase: RtlPhase, now_s: float, truth: VehicleStateTruth
    ) -> RtlPhase | None:
        down = truth.position_ned_m[2]
        fixed_wing = self._airframe.in_fixed_wing_flight
        if phase == RtlPhase.CLIMBING:
            reached = down <= self._rtl_return_down_m + ALTITUDE_REACHED_M
            return RtlPhase.MOVE_TO_LOITER if reached else None
        if phase == RtlPhase.MOVE_TO_LOITER:
            reached = self._home_distance_m(truth) <= self._reach_radius_m(fixed_wing)
            return RtlPhase.LOITER_DOWN if reached else None
        if phase == RtlPhase.LOITER_DOWN:
            reached = down >= self._rtl_descend_down_m - ALTITUDE_REACHED_M
            return RtlPhase.LOITER_HOLD if reached else None
        if phase == RtlPhase.LOITER_HOLD:
            delay = self._params.get("RTL_LAND_DELAY")
            if delay < 0 or now_s - self._rtl_phase_started_s < delay:
                return None
            # rtl_direct: only a VTOL in fixed-wing flight flies an approach and transitions;
            # a plane goes on to land where it loiters.
            vtol_in_fw = fixed_wing and self._airframe.is_vtol
            return RtlPhase.MOVE_TO_LAND if vtol_in_fw else RtlPhase.MOVE_TO_LAND_HOVER
        if phase == RtlPhase.MOVE_TO_LAND:
            near = self._home_distance_m(truth) <= self._back_transition_distance_m(truth)
            return RtlPhase.TRANSITION_TO_MC if near or not fixed_wing else None
        if phase == RtlPhase.TRANSITION_TO_MC:
            in_mc = self._airframe.vtol_state == VtolState.MC
            return RtlPhase.MOVE_TO_LAND_HOVER if in_mc else None
        if phase == RtlPhase.MOVE_TO_LAND_HOVER:
            near = self._home_distance_m(truth) <= self._reach_radius_m(fixed_wing)
            return RtlPhase.LAND if near else None
        if phase == RtlPhase.LAND:
            if self._ground_vehicle:
                return RtlPhase.IDLE  # arrived: a rover stops and stays armed
            return RtlPhase.IDLE if self._commander.landed else None
        return None

    def _rtl_setpoint(
        self, phase: RtlPhase, truth: VehicleStateTruth
    ) -> TrajectorySetpoint | None:
        home = self._commander.home
        if phase == RtlPhase.IDLE:
            return None
        if phase == RtlPhase.LAND:
            return self._land(truth, self._land_xy)
        if phase == RtlPhase.CLIMBING:
            north, east = self._rtl_climb_xy
            return TrajectorySetpoint(
                position_ned_m=[north, east, self._rtl_return_down_m], yaw_rad=self._hold_yaw_rad
            )
        if phase == RtlPhase.MOVE_TO_LAND and self._airframe.in_fixed_wing_flight:
            return self._approach_home(truth)
        if phase == RtlPhase.TRANSITION_TO_MC:
            self._airframe.request_transition(to_fixed_wing=False, immediate=False)
        down = self._rtl_descend_down_m
        if phase == RtlPhase.MOVE_TO_LOITER:
            down = self._rtl_return_down_m
        return TrajectorySetpoint(
            position_ned_m=[home.position_ned_m[0], home.position_ned_m[1], down],
            yaw_rad=self._return_yaw_rad(truth),
            max_speed_xy_m_s=self._params.get("MPC_XY_CRUISE"),
        )

    def _reach_radius_m(self, fixed_wing: bool) -> float:
        """A multicopter arrives over a point; a fixed wing once on its loiter circle."""
        if fixed_wing:
            return self._params.get("NAV_LOITER_RAD") * FW_LOITER_REACHED_FACTOR
        return MC_POSITION_REACHED_M

    def _back_transition_distance_m(self, truth: VehicleStateTruth) -> float:
        """PX4's acceptance radius of a waypoint with a back transition: the distance the
        VTOL needs to stop from its ground speed at VT_B_DEC_MSS."""
        velocity = truth.velocity_ned_m_s
        speed = math.hypot(velocity[0], velocity[1])
        deceleration = self._params.get("VT_B_DEC_MSS")
        if deceleration <= 0.0:
            return MC_POSITION_REACHED_M
        return max(speed * speed / (2.0 * deceleration), MC_POSITION_REACHED_M)

    def _approach_home(self, truth: VehicleStateTruth) -> TrajectorySetpoint:
        """Fixed-wing flight straight at home at the descend altitude (a course, so the
        wing does not settle on a loiter circle around it)."""
        home = self._commander.home.position_ned_m
        bearing = math.atan2(
            home[1] - truth.position_ned_m[1], home[0] - truth.position_ned_m[0]
        )
        speed = self._params.get("FW_AIRSPD_TRIM")
        return TrajectorySetpoint(
            position_ned_m=[math.nan, math.nan, self._rtl_descend_down_m],
            velocity_ned_m_s=[speed * math.cos(bearing), speed * math.sin(bearing), math.nan],
        )

    def _return_yaw_rad(self, truth: VehicleStateTruth) -> float:
        """Towards home while far, home's yaw within RTL_MIN_DIST (seed 004)."""
        home = self._commander.home
        if self._home_distance_m(truth) < self._params.get("RTL_MIN_DIST"):
            return home.yaw_rad
        return math.atan2(
            home.position_ned_m[1] - truth.position_ned_m[1],
            home.position_ned_m[0] - truth.position_ned_m[0],
        )
