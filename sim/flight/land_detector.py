"""Landed / in-air detection from the estimated state, after PX4's land_detector.

PX4 reports "landed" only once the vehicle has rested on the ground for a while
(maybe_landed then landed), and "in air" as soon as it clearly lifts off.
"""

from __future__ import annotations

from enum import IntEnum

from sim.lib.topics import VehicleStateTruth

# Time the ground condition must hold before the state flips to landed.
LAND_DETECT_TIME_S = 0.3
TAKEOFF_ALTITUDE_M = 0.3
REST_SPEED_M_S = 0.3


class MavLandedState(IntEnum):
    """MAV_LANDED_STATE, as in EXTENDED_SYS_STATE.landed_state."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class LandDetector:
    def __init__(self, ground_vehicle: bool = False) -> None:
        self.landed = True
        self._ground_vehicle = ground_vehicle
        self._ground_time_s = 0.0

    def update(self, dt_s: float, truth: VehicleStateTruth, armed: bool) -> None:
        if self._ground_vehicle:
            # PX4's rover land detector: landed exactly while disarmed.
            self.landed = not armed
            return
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
