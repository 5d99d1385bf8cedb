"""The telemetry messages of the simulated vehicle, each built from its current state,
after PX4's mavlink_messages: heartbeat, attitude, positions, status, home, versions."""

from __future__ import annotations

import math
from collections.abc import Callable

from pymavlink.dialects.v20 import development as mavlink

from sim.lib.mavlink_custom import (
    MAVLINK_MSG_ID_LINK_NODE_STATUS as MAVLINK_MSG_ID_LINK_NODE_STATUS,
)
from sim.lib.mavlink_custom import (
    MAVLINK_MSG_ID_PROTOCOL_VERSION as MAVLINK_MSG_ID_PROTOCOL_VERSION,
)
from sim.lib.mavlink_custom import (
    MAVLINK_MSG_ID_TIME_ESTIMATE_TO_TARGET as MAVLINK_MSG_ID_TIME_ESTIMATE_TO_TARGET,
)
from sim.lib.mavlink_custom import ProtocolVersionMessage as ProtocolVersionMessage
from sim.lib.quat import euler_from_quat, yaw_from_quat
from sim.mavlink.mavlink_telemetry import TelemetryMessages, centidegrees
from sim.mavlink.vehicle_interface import Message, VehicleInterface

# MAV_SYS_STATUS_SENSOR bits of a healthy SIH vehicle; MAVSDK's health_all_ok needs
# gyro, accel, mag, GPS (present and healthy) and the pre-arm bit.
_SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
    | mavlink.MAV_SYS_STATUS_AHRS
    | mavlink.MAV_SYS_STATUS_PREARM_CHECK
)
_SENSORS_BEFORE_GPS_FIX = _SENSORS & ~(
    mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_PREARM_CHECK
)

# mavlink_main.cpp send_autopilot_capabilities() of PX4 v1.16 (0xE8FF, as its SITL
# reports): no SET_POSITION_TARGET_GLOBAL_INT bit although PX4 takes that message; the
# gimbal manager bit only with MNT_MODE_IN = 4, which SIH vehicles do not set.
PX4_CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | mavlink.MAV_PROTOCOL_CAPABILITY_FTP
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_FLIGHT_TERMINATION
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
)
# PX4 v1.16.0, FIRMWARE_VERSION_TYPE_OFFICIAL (flight and middleware version alike).
PX4_FLIGHT_SW_VERSION = (1 << 24) | (16 << 16) | (0 << 8) | 255
# the first five bytes of the v1.16.0 tag's git hash (PX4_GIT_VERSION_BINARY
# 0x6ea3539157ca358c), little-endian after three zero vendor-version bytes, as PX4 packs them
PX4_FLIGHT_CUSTOM_VERSION = [0, 0, 0, 0x57, 0x91, 0x53, 0xA3, 0x6E]
# PROTOCOL_VERSION.library_version_hash: the c_library's git hash PX4 v1.16.0 was built with
# (MAVLINK_LIB_GIT_VERSION_BINARY 0x5bfd76d80281f602, little-endian); its spec hash is zero
MAVLINK_LIB_GIT_VERSION = (0x5BFD76D80281F602).to_bytes(8, "little")
# SITL's os_sw_version and board_version
PX4_OS_SW_VERSION = 101854463
PX4_BOARD_VERSION = 1
# what PX4's SIH GPS reports (MAVSDK's gps_info shows it on PX4 v1.16 SITL)
SIH_SATELLITES_VISIBLE = 10
# GPS_RAW_INT h_acc, v_acc (mm) and vel_acc (mm/s) of SIH's GPS
_SIH_GPS_ACCURACY_MM = (900, 1780, 400)
# STATUSTEXT.text is 50 bytes; a longer text goes out in chunks (MAVLink 2's id and seq)
STATUSTEXT_MAX_LEN = 50


# MAVLink 2 spoken, MAVLink 1 and 2 understood (PROTOCOL_VERSION.version = 100 * major).
MAVLINK_VERSION_2 = 200
MAVLINK_VERSION_1 = 100


def _charge_state(remaining_percent: int) -> int:
    """MAV_BATTERY_CHARGE_STATE by PX4's default BAT_LOW_THR, BAT_CRIT_THR, BAT_EMERGEN_THR."""
    if remaining_percent > 15:
        return int(mavlink.MAV_BATTERY_CHARGE_STATE_OK)
    if remaining_percent > 7:
        return int(mavlink.MAV_BATTERY_CHARGE_STATE_LOW)
    if remaining_percent > 5:
        return int(mavlink.MAV_BATTERY_CHARGE_STATE_CRITICAL)
    return int(mavlink.MAV_BATTERY_CHARGE_STATE_EMERGENCY)


def _pwm(output: float) -> int:
    return round(1000.0 + 1000.0 * min(max(output, 0.0), 1.0))


class MessageFactory:
    """Builds each telemetry message from the vehicle's current state."""

    def __init__(self, vehicle: VehicleInterface) -> None:
        self._v = vehicle
        self._statustext_id = 0
        # what was built at this sim time: a message due on both links is built once
        self._built: dict[int, tuple[float, Message | None]] = {}
        sensors = TelemetryMessages(vehicle)
        self.builders: dict[int, Callable[[], Message | None]] = {
            mavlink.MAVLINK_MSG_ID_HEARTBEAT: self.heartbeat,
            mavlink.MAVLINK_MSG_ID_SYS_STATUS: self.sys_status,
            mavlink.MAVLINK_MSG_ID_ATTITUDE: self.attitude,
            mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: self.attitude_quaternion,
            mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self.local_position_ned,
            mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self.global_position_int,
            mavlink.MAVLINK_MSG_ID_VFR_HUD: self.vfr_hud,
            mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: self.gps_raw_int,
            mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: self.battery_status,
            mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self.extended_sys_state,
            mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: self.position_target_local_ned,
            mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: self.servo_output_raw,
            mavlink.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: self.actuator_output_status,
            mavlink.MAVLINK_MSG_ID_HOME_POSITION: self.home_position,
            mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: self.gps_global_origin,
            mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self.autopilot_version,
            mavlink.MAVLINK_MSG_ID_CURRENT_MODE: self.current_mode,
            MAVLINK_MSG_ID_PROTOCOL_VERSION: self.protocol_version,
            mavlink.MAVLINK_MSG_ID_ALTITUDE: sensors.altitude,
            mavlink.MAVLINK_MSG_ID_HIGHRES_IMU: sensors.highres_imu,
            mavlink.MAVLINK_MSG_ID_ODOMETRY: sensors.odometry,
            mavlink.MAVLINK_MSG_ID_ESTIMATOR_STATUS: sensors.estimator_status,
            mavlink.MAVLINK_MSG_ID_VIBRATION: sensors.vibration,
            mavlink.MAVLINK_MSG_ID_SCALED_PRESSURE: sensors.scaled_pressure,
            mavlink.MAVLINK_MSG_ID_TIMESYNC: sensors.timesync,
            mavlink.MAVLINK_MSG_ID_PING: sensors.ping,
            mavlink.MAVLINK_MSG_ID_SYSTEM_TIME: sensors.system_time,
            mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR: sensors.distance_sensor,
            mavlink.MAVLINK_MSG_ID_ATTITUDE_TARGET: sensors.attitude_target,
            mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: sensors.mission_current,
            mavlink.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT: sensors.nav_controller_output,
            mavlink.MAVLINK_MSG_ID_OPEN_DRONE_ID_LOCATION: sensors.open_drone_id_location,
            mavlink.MAVLINK_MSG_ID_OPEN_DRONE_ID_SYSTEM: sensors.open_drone_id_system,
            MAVLINK_MSG_ID_LINK_NODE_STATUS: sensors.link_node_status,
            MAVLINK_MSG_ID_TIME_ESTIMATE_TO_TARGET: sensors.time_estimate_to_target,
        }

    def build(self, msg_id: int) -> Message | None:
        """msg_id's message from the current state (None: unknown or not available yet)."""
        builder = self.builders.get(msg_id)
        return builder() if builder is not None else None

    def build_streamed(self, msg_id: int) -> Message | None:
        """build(), but one object for every link whose stream is due at this sim time
        (streams are all sent from one step, where the state does not change)."""
        now_s = self._v.now_s
        built = self._built.get(msg_id)
        if built is not None and built[0] == now_s:
            return built[1]
        msg = self.build(msg_id)
        self._built[msg_id] = (now_s, msg)
        return msg

    def statustexts(self, severity: int, text: str) -> list[Message]:
        # PX4's texts end with a tab (mavlink_log_critical(..., "...\t")); it is chunked too
        data = text.removesuffix("\t").encode() + b"\t"
        if len(data) <= STATUSTEXT_MAX_LEN:
            return [mavlink.MAVLink_statustext_message(severity, data)]
        self._statustext_id = self._statustext_id % 65535 + 1
        return [
            mavlink.MAVLink_statustext_message(
                severity, data[start:start + STATUSTEXT_MAX_LEN], self._statustext_id, seq)
            for seq, start in enumerate(range(0, len(data), STATUSTEXT_MAX_LEN))
        ]

    @property
    def _boot_ms(self) -> int:
        return int(self._v.now_s * 1000.0)

    def heartbeat(self) -> Message:
        v = self._v
        commander = v.commander
        if not commander.armed:
            status = mavlink.MAV_STATE_STANDBY
        elif commander.failsafe:
            status = mavlink.MAV_STATE_CRITICAL
        else:
            status = mavlink.MAV_STATE_ACTIVE
        mode = commander.nav_mode
        return mavlink.MAVLink_heartbeat_message(
            v.mav_type, mavlink.MAV_AUTOPILOT_PX4, mode.base_mode(commander.armed),
            mode.custom_mode, status, 3,
        )

    def sys_status(self) -> Message:
        v = self._v
        sensors = _SENSORS if v.ready else _SENSORS_BEFORE_GPS_FIX
        health = sensors if v.can_arm else sensors & ~mavlink.MAV_SYS_STATUS_PREARM_CHECK
        battery = v.battery
        return mavlink.MAVLink_sys_status_message(
            sensors, sensors, health, 250, round(battery.voltage_v * 1000.0),
            round(battery.current_a * 100.0), battery.remaining_percent, 0, 0, 0, 0, 0, 0,
        )

    def attitude(self) -> Message:
        truth = self._v.truth
        roll, pitch, yaw = euler_from_quat(truth.q_wxyz)
        p, q, r = truth.rates_body_rad_s
        return mavlink.MAVLink_attitude_message(self._boot_ms, roll, pitch, yaw, p, q, r)

    def attitude_quaternion(self) -> Message:
        truth = self._v.truth
        w, x, y, z = truth.q_wxyz
        p, q, r = truth.rates_body_rad_s
        return mavlink.MAVLink_attitude_quaternion_message(self._boot_ms, w, x, y, z, p, q, r)

    def local_position_ned(self) -> Message | None:
        if not self._v.ready:
            return None
        north, east, down = self._v.truth.position_ned_m
        vn, ve, vd = self._v.truth.velocity_ned_m_s
        return mavlink.MAVLink_local_position_ned_message(
            self._boot_ms, north, east, down, vn, ve, vd
        )

    def global_position_int(self) -> Message | None:
        v = self._v
        if not v.ready:
            return None
        geo = v.geodetic()
        vn, ve, vd = v.truth.velocity_ned_m_s
        relative_alt_m = v.commander.home.position_ned_m[2] - v.truth.position_ned_m[2]
        heading_cdeg = centidegrees(yaw_from_quat(v.truth.q_wxyz))
        return mavlink.MAVLink_global_position_int_message(
            self._boot_ms, round(geo.lat_deg * 1e7), round(geo.lon_deg * 1e7),
            round(geo.alt_m * 1000.0), round(relative_alt_m * 1000.0),
            round(vn * 100.0), round(ve * 100.0), round(vd * 100.0), heading_cdeg,
        )

    def vfr_hud(self) -> Message:
        v = self._v
        vn, ve, vd = v.truth.velocity_ned_m_s
        heading_deg = round(math.degrees(yaw_from_quat(v.truth.q_wxyz)) % 360.0) % 360
        throttle = round(100.0 * v.model.power_fraction) if v.commander.armed else 0
        return mavlink.MAVLink_vfr_hud_message(
            v.truth.airspeed_m_s, math.hypot(vn, ve), heading_deg, throttle,
            v.geodetic().alt_m, -vd,
        )

    def gps_raw_int(self) -> Message:
        v = self._v
        if not v.ready:
            return mavlink.MAVLink_gps_raw_int_message(
                int(v.now_s * 1e6), 1, 0, 0, 0, 9999, 9999, 0, 0, 0
            )
        geo = v.geodetic()
        vn, ve, _ = v.truth.velocity_ned_m_s
        cog_cdeg = centidegrees(math.atan2(ve, vn))
        return mavlink.MAVLink_gps_raw_int_message(
            int(v.now_s * 1e6), 3, round(geo.lat_deg * 1e7), round(geo.lon_deg * 1e7),
            round(geo.alt_m * 1000.0), 70, 100, round(math.hypot(vn, ve) * 100.0), cog_cdeg,
            SIH_SATELLITES_VISIBLE, round(geo.alt_m * 1000.0), *_SIH_GPS_ACCURACY_MM,
        )

    def battery_status(self) -> Message:
        battery = self._v.battery
        cell_mv = round(battery.cell_voltage_v * 1000.0)
        voltages = [cell_mv] * battery.cell_count + [65535] * (10 - battery.cell_count)
        return mavlink.MAVLink_battery_status_message(
            0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 32767,
            voltages[:10], round(battery.current_a * 100.0), round(battery.consumed_mah),
            -1, battery.remaining_percent, 0, _charge_state(battery.remaining_percent),
        )

    def extended_sys_state(self) -> Message:
        v = self._v
        return mavlink.MAVLink_extended_sys_state_message(int(v.vtol_state), v.landed_state)

    def position_target_local_ned(self) -> Message:
        sp = self._v.last_trajectory_setpoint
        position = sp.position_ned_m if sp is not None else [math.nan] * 3
        velocity = sp.velocity_ned_m_s if sp is not None else [math.nan] * 3
        accel = sp.acceleration_ned_m_s2 if sp is not None else [math.nan] * 3
        yaw = sp.yaw_rad if sp is not None else math.nan
        yaw_rate = sp.yawspeed_rad_s if sp is not None else math.nan
        return mavlink.MAVLink_position_target_local_ned_message(
            self._boot_ms, mavlink.MAV_FRAME_LOCAL_NED, 0, *position, *velocity, *accel,
            yaw, yaw_rate,
        )

    def servo_output_raw(self) -> Message:
        outputs = self._v.model.actuator_outputs if self._v.commander.armed else []
        pwm = [_pwm(u) for u in outputs[:16]] + [0] * (16 - min(len(outputs), 16))
        return mavlink.MAVLink_servo_output_raw_message(int(self._v.now_s * 1e6), 0, *pwm)

    def actuator_output_status(self) -> Message:
        outputs = list(self._v.model.actuator_outputs[:32])
        active = (1 << len(outputs)) - 1
        return mavlink.MAVLink_actuator_output_status_message(
            int(self._v.now_s * 1e6), active, outputs + [0.0] * (32 - len(outputs))
        )

    def home_position(self) -> Message | None:
        home = self._v.commander.home
        if not home.valid:
            return None
        half_yaw = home.yaw_rad / 2.0
        return mavlink.MAVLink_home_position_message(
            round(home.lat_deg * 1e7), round(home.lon_deg * 1e7), round(home.alt_m * 1000.0),
            *home.position_ned_m, [math.cos(half_yaw), 0.0, 0.0, math.sin(half_yaw)],
            0.0, 0.0, 0.0, int(self._v.now_s * 1e6),
        )

    def gps_global_origin(self) -> Message | None:
        if not self._v.ready:
            return None
        origin = self._v.origin
        return mavlink.MAVLink_gps_global_origin_message(
            round(origin.lat_deg * 1e7), round(origin.lon_deg * 1e7),
            round(origin.alt_m * 1000.0), int(self._v.now_s * 1e6),
        )

    def autopilot_version(self) -> Message:
        sysid = self._v.sysid
        return mavlink.MAVLink_autopilot_version_message(
            PX4_CAPABILITIES, PX4_FLIGHT_SW_VERSION, PX4_FLIGHT_SW_VERSION, PX4_OS_SW_VERSION,
            PX4_BOARD_VERSION, PX4_FLIGHT_CUSTOM_VERSION, PX4_FLIGHT_CUSTOM_VERSION, [0] * 8,
            0, 0, 0x5348_0000 + sysid, [sysid] + [0] * 17,
        )

    def protocol_version(self) -> Message:
        return ProtocolVersionMessage(MAVLINK_VERSION_2, MAVLINK_VERSION_1, MAVLINK_VERSION_2,
                                      bytes(8), MAVLINK_LIB_GIT_VERSION)

    def current_mode(self) -> Message:
        commander = self._v.commander
        return mavlink.MAVLink_current_mode_message(
            int(commander.nav_mode.standard_mode), commander.nav_mode.custom_mode,
            commander.user_mode.custom_mode,
        )
