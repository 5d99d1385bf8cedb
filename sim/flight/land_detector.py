"""Landed / in-air detection, after PX4's land_detector.

A multicopter (and a VTOL hovering) goes through PX4's three stages, each of which must
hold for LNDMC_TRIG_TIME / 3 (three times that without a valid range finder) before the
next may start: ground contact (low thrust while descending, no vertical or horizontal
movement, close to the ground), maybe landed (thrust at its minimum, no rotation), landed.
Any stage ends at once when its conditions fail, so a vehicle whose thrust rises is in the
air again before it lifts off. The thrust and velocity setpoints come from the position
controller (`LandingStatus`), which in turn cuts the thrust once ground contact is seen.

A plane (or a VTOL in fixed-wing flight) is landed once it rests on the ground; a rover is
landed exactly while disarmed.
"""

from __future__ import annotations

import math
from enum import IntEnum

from sim.lib.params import ParamReader
from sim.lib.topics import LandingStatus, VehicleStateTruth

# Fixed-wing detection: time the ground condition must hold before the state flips.
LAND_DETECT_TIME_S = 0.3
TAKEOFF_ALTITUDE_M = 0.3
REST_SPEED_M_S = 0.3
# MulticopterLandDetector: close to the ground below this range-finder distance
DIST_FROM_GROUND_THRESHOLD_M = 1.0
# the simulated range finder's reach (DISTANCE_SENSOR max_distance)
RANGE_FINDER_MAX_M = 100.0
# share of hover thrust above MPC_THR_MIN that counts as low (hover thrust estimate valid)
LOW_THRUST_SHARE = 0.6
MINIMUM_THRUST_SHARE = 0.1
# thresholds widen by this factor once landed
LANDED_THRESHOLD_FACTOR = 2.5


class MavLandedState(IntEnum):
    """MAV_LANDED_STATE, as in EXTENDED_SYS_STATE.landed_state."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class Hysteresis:
    """PX4 systemlib::Hysteresis with a delay from false to true only."""

    def __init__(self, state: bool) -> None:
        self.state = state
        self._requested = state
        self._requested_at_s = 0.0

    def update(self, wanted: bool, now_s: float, rise_time_s: float) -> None:
        if wanted == self.state:
            self._requested = wanted
            return
        if wanted != self._requested:
            self._requested = wanted
            self._requested_at_s = now_s
        delay = rise_time_s if wanted else 0.0
        if now_s - self._requested_at_s >= delay - 1e-9:
            self.state = wanted

    def force(self, state: bool) -> None:
        self.state = self._requested = state


class LandDetector:
    def __init__(self, ground_vehicle: bool = False, params: ParamReader | None = None) -> None:
        self.landed = True
        self._ground_vehicle = ground_vehicle
        self._params = params
        self._ground_time_s = 0.0
        self._now_s = 0.0
        self._ground_contact = Hysteresis(True)
        self._maybe_landed = Hysteresis(True)
        self._landed = Hysteresis(True)

    def update(
        self,
        dt_s: float,
        truth: VehicleStateTruth,
        armed: bool,
        landing: LandingStatus | None = None,
        fixed_wing: bool = False,
    ) -> None:
        self._now_s += dt_s
        if self._ground_vehicle:
            # PX4's rover land detector: landed exactly while disarmed.
            self.landed = not armed
            return
        if landing is not None:
            landing.detector_attached = True
        if landing is None or self._params is None or fixed_wing:
            self._fixed_wing(dt_s, truth, armed)
            self._multicopter_follows(self.landed, landing)
            return
        self._multicopter(truth, armed, landing)

    def _multicopter_follows(self, landed: bool, landing: LandingStatus | None) -> None:
        for stage in (self._ground_contact, self._maybe_landed, self._landed):
            stage.force(landed)
        if landing is not None:
            landing.landed = landing.maybe_landed = landing.ground_contact = landed

    def _multicopter(self, truth: VehicleStateTruth, armed: bool, landing: LandingStatus) -> None:
        """MulticopterLandDetector: ground contact → maybe landed → landed."""
        params = self._params
        assert params is not None
        now = self._now_s
        if not armed:
            self.landed = True
            self._multicopter_follows(True, landing)
            return
        height_m = -truth.position_ned_m[2]
        range_valid = 0.0 <= height_m <= RANGE_FINDER_MAX_M
        stage_s = params.get("LNDMC_TRIG_TIME") / 3.0 * (1.0 if range_valid else 3.0)
        thr_min = params.get("MPC_THR_MIN")
        hover = landing.hover_thrust
        thrust = landing.thrust_setpoint
        landed_before = self._landed.state
        widen = LANDED_THRESHOLD_FACTOR if landed_before else 1.0

        z_vel_max = min(params.get("LNDMC_Z_VEL_MAX"),
                        min(params.get("MPC_LAND_CRWL"), params.get("MPC_LAND_SPEED")) / 1.2)
        vx, vy, vz = truth.velocity_ned_m_s
        vertical_movement = abs(vz) >= z_vel_max * widen
        horizontal_movement = math.hypot(vx, vy) > params.get("LNDMC_XY_VEL_MAX")
        ground_contact = thrust <= thr_min + (hover - thr_min) * LOW_THRUST_SHARE
        if landing.climb_rate_controlled:
            vel_sp = landing.velocity_setpoint_down_m_s
            in_descend = math.isfinite(vel_sp) and vel_sp >= 1.1 * z_vel_max
            if not self._maybe_landed.state and not landed_before:
                ground_contact = ground_contact and in_descend
        close_or_unknown = not range_valid or height_m < DIST_FROM_GROUND_THRESHOLD_M
        self._ground_contact.update(
            close_or_unknown and ground_contact and not horizontal_movement
            and not vertical_movement, now, stage_s)

        if landing.climb_rate_controlled:
            minimum_thrust = thr_min + (hover - thr_min) * MINIMUM_THRUST_SHARE
        else:
            minimum_thrust = params.get("MPC_MANTHR_MIN") + 0.01
        wx, wy, _ = truth.rates_body_rad_s
        rotating = math.hypot(wx, wy) > math.radians(params.get("LNDMC_ROT_MAX")) * widen
        self._maybe_landed.update(
            thrust <= minimum_thrust and not rotating and self._ground_contact.state,
            now, stage_s)
        self._landed.update(self._maybe_landed.state, now, stage_s)

        self.landed = self._landed.state
        landing.landed = self._landed.state
        landing.maybe_landed = self._maybe_landed.state
        landing.ground_contact = self._ground_contact.state

    def _fixed_wing(self, dt_s: float, truth: VehicleStateTruth, armed: bool) -> None:
        down_m = truth.position_ned_m[2]
        vz = truth.velocity_ned_m_s[2]
        on_ground = truth.on_ground or (-down_m < 0.05 and abs(vz) < REST_SPEED_M_S)
        if not armed and on_ground:
            self.landed = True
            self._ground_time_s = LAND_DETECT_TIME_S
            return
        if on_ground:
            self._ground_time_s += dt_s
            if self._ground_time_s >= LAND_DETECT_TIME_S:
                self.landed = True
        else:
            self._ground_time_s = 0.0
            if -down_m > TAKEOFF_ALTITUDE_M or not self.landed:
                self.landed = False

    def reset(self) -> None:
        self.landed = True
        self._ground_time_s = LAND_DETECT_TIME_S
        self._multicopter_follows(True, None)
