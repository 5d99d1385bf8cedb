"""The sensor, estimator and housekeeping messages of PX4's onboard stream set, built from
the simulated vehicle's state: what a SIH vehicle's sensors would read (an ideal IMU, a
magnetometer in a fixed earth field, an ISA barometer, a downward range finder), what its
estimator would report (healthy once the GPS fix is in), and PX4's link housekeeping
(TIMESYNC and PING requests, SYSTEM_TIME, LINK_NODE_STATUS)."""

from __future__ import annotations

import math
import time

from pymavlink.dialects.v20 import development as mavlink

from sim.lib.mavlink_custom import LinkNodeStatusMessage, TimeEstimateToTargetMessage
from sim.lib.quat import euler_from_quat, rotate_ned_to_body
from sim.mavlink.vehicle_interface import Message, VehicleInterface

GRAVITY_M_S2 = 9.80665
# Earth field (gauss, NED) near SIH's default home (Zurich); only its direction matters here.
_MAG_NED_GAUSS = (0.21, 0.015, 0.43)
# ISA troposphere: sea-level pressure and temperature, lapse rate
_P0_PA = 101325.0
_T0_K = 288.15
_LAPSE_K_M = 0.0065
_BARO_EXPONENT = 5.25588
SIH_AMBIENT_TEMPERATURE_C = 15.0
# SIH's downward range finder (SIH_DISTSNSR_MIN / _MAX)
DISTANCE_SENSOR_MIN_M = 0.0
DISTANCE_SENSOR_MAX_M = 100.0
# HIGHRES_IMU.fields_updated: accel, gyro, mag, abs pressure, pressure altitude, temperature
_HIGHRES_FIELDS = 0b1_1101_1111_1111
# PX4 estimator_status flags of a converged EKF2 with GPS
_EKF_OK = (
    mavlink.ESTIMATOR_ATTITUDE | mavlink.ESTIMATOR_VELOCITY_HORIZ
    | mavlink.ESTIMATOR_VELOCITY_VERT | mavlink.ESTIMATOR_POS_HORIZ_REL
    | mavlink.ESTIMATOR_POS_HORIZ_ABS | mavlink.ESTIMATOR_POS_VERT_ABS
    | mavlink.ESTIMATOR_POS_VERT_AGL | mavlink.ESTIMATOR_PRED_POS_HORIZ_REL
    | mavlink.ESTIMATOR_PRED_POS_HORIZ_ABS
)
_EKF_BEFORE_GPS = mavlink.ESTIMATOR_ATTITUDE | mavlink.ESTIMATOR_VELOCITY_VERT
NO_MISSION_TOTAL = 0xFFFF
MAV_ODID_STATUS_GROUND = 1
MAV_ODID_STATUS_AIRBORNE = 2
MAV_ODID_HEIGHT_REF_OVER_TAKEOFF = 0
MAV_ODID_OPERATOR_LOCATION_TYPE_TAKEOFF = 0
_COVARIANCE_DIAGONAL = (0, 6, 11, 15, 18, 20)


def pressure_pa(alt_amsl_m: float) -> float:
    """ISA static pressure at an altitude above mean sea level."""
    return _P0_PA * float(max(1.0 - _LAPSE_K_M * alt_amsl_m / _T0_K, 0.01) ** _BARO_EXPONENT)


def centidegrees(angle_rad: float) -> int:
    """An angle as MAVLink's headings carry it: 0..35999 cdeg."""
    return round(math.degrees(angle_rad) % 360.0 * 100.0) % 36000


def _covariance(variance: float) -> list[float]:
    """PX4's upper-triangular 6×6 covariance with only the diagonal known."""
    values = [0.0] * 21
    for index in _COVARIANCE_DIAGONAL:
        values[index] = variance
    return values


_POSE_COVARIANCE = _covariance(0.01)
_VELOCITY_COVARIANCE = _covariance(0.0025)


class TelemetryMessages:
    """Builders of the sensor, estimator and housekeeping messages."""

    def __init__(self, vehicle: VehicleInterface) -> None:
        self._v = vehicle
        self._ping_seq = 0
        self._unix_at_boot_us = int(time.time() * 1e6)

    @property
    def _time_us(self) -> int:
        return int(self._v.now_s * 1e6)

    def _alt_amsl_m(self) -> float:
        return self._v.origin.alt_m - self._v.truth.position_ned_m[2]

    def _height_m(self) -> float:
        """Height above the (flat) ground at the local origin."""
        return max(-self._v.truth.position_ned_m[2], 0.0)

    def altitude(self) -> Message:
        v = self._v
        down = v.truth.position_ned_m[2]
        amsl = self._alt_amsl_m()
        relative = v.commander.home.position_ned_m[2] - down
        return mavlink.MAVLink_altitude_message(
            self._time_us, amsl, amsl, -down, relative, self._height_m(), self._height_m()
        )

    def highres_imu(self) -> Message:
        truth = self._v.truth
        q = truth.q_wxyz
        a = truth.acceleration_ned_m_s2
        # an accelerometer reads specific force: acceleration minus gravity, in body axes
        acc = rotate_ned_to_body(q, (a[0], a[1], a[2] - GRAVITY_M_S2))
        mag = rotate_ned_to_body(q, _MAG_NED_GAUSS)
        p, r_pitch, r_yaw = truth.rates_body_rad_s
        amsl = self._alt_amsl_m()
        # PX4 fills abs_pressure in Pa (the spec says hPa) and the temperature with
        # air_data's ambient temperature, which SIH leaves at 15 °C
        return mavlink.MAVLink_highres_imu_message(
            self._time_us, *acc, p, r_pitch, r_yaw, *mag, pressure_pa(amsl), 0.0, amsl,
            SIH_AMBIENT_TEMPERATURE_C, _HIGHRES_FIELDS, 0,
        )

    def odometry(self) -> Message | None:
        v = self._v
        if not v.ready:
            return None
        truth = v.truth
        # EKF2's odometry has its velocity in NED, so PX4 names LOCAL_NED as child frame too
        return mavlink.MAVLink_odometry_message(
            self._time_us, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_NED,
            *truth.position_ned_m, list(truth.q_wxyz), *truth.velocity_ned_m_s,
            *truth.rates_body_rad_s, _POSE_COVARIANCE, _VELOCITY_COVARIANCE, 0,
            mavlink.MAV_ESTIMATOR_TYPE_AUTOPILOT, 100,
        )

    def estimator_status(self) -> Message:
        ready = self._v.ready
        return mavlink.MAVLink_estimator_status_message(
            self._time_us, _EKF_OK if ready else _EKF_BEFORE_GPS, 0.05, 0.02, 0.03, 0.04,
            0.0, math.nan, 0.3 if ready else math.inf, 0.5 if ready else math.inf,
        )

    def vibration(self) -> Message:
        # grows with the motors' power, as an IMU on a frame with spinning props shows
        level = 0.02 + 0.2 * self._v.model.power_fraction if self._v.commander.armed else 0.005
        return mavlink.MAVLink_vibration_message(
            self._time_us, level, level, 1.5 * level, 0, 0, 0
        )

    def scaled_pressure(self) -> Message:
        amsl = self._alt_amsl_m()
        temperature_cdeg = round((_T0_K - _LAPSE_K_M * amsl - 273.15) * 100.0)
        return mavlink.MAVLink_scaled_pressure_message(
            int(self._v.now_s * 1000.0), pressure_pa(amsl) / 100.0, 0.0, temperature_cdeg, 0
        )

    def timesync(self) -> Message:
        # PX4's periodic TIMESYNC is a request: tc1 = 0, ts1 = its clock in ns
        return mavlink.MAVLink_timesync_message(0, int(self._v.now_s * 1e9))

    def ping(self) -> Message:
        self._ping_seq = (self._ping_seq + 1) & 0xFFFFFFFF
        return mavlink.MAVLink_ping_message(self._time_us, self._ping_seq, 0, 0)

    def system_time(self) -> Message:
        return mavlink.MAVLink_system_time_message(
            self._unix_at_boot_us + self._time_us, int(self._v.now_s * 1000.0)
        )

    def distance_sensor(self) -> Message:
        truth = self._v.truth
        # range along the body's down axis to flat ground
        body_z_down = 1.0 - 2.0 * (truth.q_wxyz[1] ** 2 + truth.q_wxyz[2] ** 2)
        distance_m = self._height_m() / max(body_z_down, 0.1)
        distance_cm = round(min(max(distance_m, DISTANCE_SENSOR_MIN_M), DISTANCE_SENSOR_MAX_M)
                            * 100.0)
        return mavlink.MAVLink_distance_sensor_message(
            int(self._v.now_s * 1000.0), round(DISTANCE_SENSOR_MIN_M * 100.0),
            round(DISTANCE_SENSOR_MAX_M * 100.0), distance_cm, mavlink.MAV_DISTANCE_SENSOR_LASER,
            0, mavlink.MAV_SENSOR_ROTATION_PITCH_270, 0,
        )

    def attitude_target(self) -> Message:
        v = self._v
        truth = v.truth
        thrust = v.model.power_fraction if v.commander.armed else 0.0
        return mavlink.MAVLink_attitude_target_message(
            int(v.now_s * 1000.0), 0, list(truth.q_wxyz), *truth.rates_body_rad_s, thrust
        )

    def nav_controller_output(self) -> Message | None:
        """Only while the fixed-wing position controller runs (a plane, a VTOL in FW), whose
        status PX4 streams: attitude, bearing and distance to the target, altitude error."""
        v = self._v
        if not v.model.in_fixed_wing_flight:
            return None
        truth = v.truth
        roll, pitch, yaw = euler_from_quat(truth.q_wxyz)
        sp = v.last_trajectory_setpoint
        target = sp.position_ned_m if sp is not None else [math.nan] * 3
        here = truth.position_ned_m
        dn, de = target[0] - here[0], target[1] - here[1]
        has_target = math.isfinite(dn) and math.isfinite(de)
        bearing_deg = round(math.degrees(yaw))
        target_deg = round(math.degrees(math.atan2(de, dn))) if has_target else bearing_deg
        distance_m = min(round(math.hypot(dn, de)), 65535) if has_target else 0
        alt_error_m = here[2] - target[2] if math.isfinite(target[2]) else 0.0
        return mavlink.MAVLink_nav_controller_output_message(
            math.degrees(roll), math.degrees(pitch), bearing_deg, target_deg, distance_m,
            alt_error_m, 0.0, 0.0,
        )

    def mission_current(self) -> Message:
        # PX4 without a mission: total UINT16_MAX, mission_state left unknown
        return mavlink.MAVLink_mission_current_message(0, NO_MISSION_TOTAL, 0, 0)

    def open_drone_id_location(self) -> Message | None:
        v = self._v
        if not v.ready:
            return None
        vn, ve, vd = v.truth.velocity_ned_m_s
        geo = v.geodetic()
        status = MAV_ODID_STATUS_GROUND if v.commander.landed else MAV_ODID_STATUS_AIRBORNE
        return mavlink.MAVLink_open_drone_id_location_message(
            0, 0, bytes(20), status, centidegrees(math.atan2(ve, vn)),
            round(math.hypot(vn, ve) * 100.0), round(-vd * 100.0),
            round(geo.lat_deg * 1e7), round(geo.lon_deg * 1e7), geo.alt_m, geo.alt_m,
            MAV_ODID_HEIGHT_REF_OVER_TAKEOFF,
            v.commander.home.position_ned_m[2] - v.truth.position_ned_m[2],
            mavlink.MAV_ODID_HOR_ACC_3_METER, mavlink.MAV_ODID_VER_ACC_3_METER,
            mavlink.MAV_ODID_VER_ACC_3_METER, mavlink.MAV_ODID_SPEED_ACC_1_METERS_PER_SECOND,
            (v.now_s % 3600.0), mavlink.MAV_ODID_TIME_ACC_0_1_SECOND,
        )

    def open_drone_id_system(self) -> Message | None:
        home = self._v.commander.home
        if not home.valid:
            return None
        return mavlink.MAVLink_open_drone_id_system_message(
            0, 0, bytes(20), MAV_ODID_OPERATOR_LOCATION_TYPE_TAKEOFF,
            mavlink.MAV_ODID_CLASSIFICATION_TYPE_UNDECLARED,
            round(home.lat_deg * 1e7), round(home.lon_deg * 1e7), 1, 0, -1000.0, -1000.0,
            mavlink.MAV_ODID_CATEGORY_EU_UNDECLARED, mavlink.MAV_ODID_CLASS_EU_UNDECLARED,
            home.alt_m, int(self._v.now_s),
        )

    def link_node_status(self) -> Message:
        return LinkNodeStatusMessage(int(self._v.now_s * 1000.0), 0, 0, 0, 0, 0, 0, 0, 0,
                                     100, 100)

    def time_estimate_to_target(self) -> Message:
        """Seconds to get home and to land at the airframe's usual speeds (land: -1 when
        landed); no mission or commanded action to estimate (-1), as PX4 on the ground."""
        v = self._v
        home = v.commander.home.position_ned_m
        here = v.truth.position_ned_m
        height_m = max(home[2] - here[2], 0.0)
        land_s = round(height_m / self._speed_m_s("MPC_LAND_SPEED", 0.7))
        distance_m = math.hypot(here[0] - home[0], here[1] - home[1])
        return_s = round(distance_m / self._speed_m_s("MPC_XY_CRUISE", 5.0)) + land_s
        landed = v.commander.landed
        return TimeEstimateToTargetMessage(return_s, -1 if landed else land_s, -1, -1, -1)

    def _speed_m_s(self, name: str, default: float) -> float:
        """A speed parameter, or PX4's multicopter default on airframes without it."""
        try:
            value = self._v.params.get(name)
        except KeyError:
            value = default
        return max(value, 0.1)
