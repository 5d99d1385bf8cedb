"""MAVLink input of the simulated vehicle, after PX4's mavlink_receiver.

Commands (COMMAND_LONG / COMMAND_INT / SET_MODE) are acked to the sender; offboard
setpoints are checked and converted exactly as PX4 does, never acked, and reported
only by STATUSTEXT when refused; parameters follow PX4's parameter protocol.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeAlias

from pymavlink.dialects.v20 import development as mavlink

from sim import modes
from sim.commander import (
    ARM_DISARM_FORCE_MAGIC,
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_DENIED,
    MAV_RESULT_FAILED,
    MAV_RESULT_TEMPORARILY_REJECTED,
    MAV_RESULT_UNSUPPORTED,
    MAV_SEVERITY_CRITICAL,
)
from sim.geo import MAVLINK_ALT_LIMIT_M, is_valid_lat_lon
from sim.modes import Px4Mode
from sim.streams import MAVLINK_MSG_ID_PROTOCOL_VERSION
from sim.topics import AttitudeSetpoint, ControlSetpoint, RatesSetpoint, TrajectorySetpoint

if TYPE_CHECKING:
    from sim.vehicle import Link, SimVehicle

# pymavlink messages carry their fields as dynamic attributes.
Message: TypeAlias = Any

# SET_POSITION_TARGET_* type_mask bits (POSITION_TARGET_TYPEMASK).
IGNORE_PX, IGNORE_PY, IGNORE_PZ = 1, 2, 4
IGNORE_VX, IGNORE_VY, IGNORE_VZ = 8, 16, 32
IGNORE_AX, IGNORE_AY, IGNORE_AZ = 64, 128, 256
FORCE_SET = 512
IGNORE_YAW = 1024
IGNORE_YAW_RATE = 2048
# SET_ATTITUDE_TARGET type_mask bits (ATTITUDE_TARGET_TYPEMASK).
IGNORE_ROLL_RATE, IGNORE_PITCH_RATE, IGNORE_YAW_RATE_BODY = 1, 2, 4
IGNORE_THROTTLE = 64
IGNORE_ATTITUDE = 128

MAV_DO_REPOSITION_FLAGS_CHANGE_MODE = 1
VTOL_TRANSITION_MC = 3
VTOL_TRANSITION_FW = 4
INT32_MAX = 2**31 - 1

# Commands PX4 answers whatever target_system says (capability and version requests).
_ANY_TARGET_COMMANDS = frozenset(
    {
        mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
        mavlink.MAV_CMD_REQUEST_PROTOCOL_VERSION,
    }
)
_VERSION_MESSAGES = frozenset(
    {mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION, MAVLINK_MSG_ID_PROTOCOL_VERSION}
)
# MC→FW transition is refused while the navigator flies these.
_NO_FRONT_TRANSITION_MODES = frozenset(
    {modes.AUTO_TAKEOFF, modes.AUTO_VTOL_TAKEOFF, modes.AUTO_LAND, modes.AUTO_RTL, modes.ORBIT}
)


@dataclass
class Command:
    """A COMMAND_LONG or COMMAND_INT with COMMAND_LONG's float params."""

    command: int
    params: list[float]
    frame: int
    is_int: bool
    source_system: int
    source_component: int


def _as_int(value: float) -> int:
    """A command param as an integer; NaN (\"unset\") and infinities count as -1."""
    return int(value) if math.isfinite(value) else -1


def _nan_if(ignored: bool, value: float) -> float:
    return math.nan if ignored else float(value)


def _vector(
    mask: int, bits: tuple[int, int, int], values: tuple[float, float, float]
) -> list[float]:
    return [_nan_if(bool(mask & bit), value) for bit, value in zip(bits, values, strict=True)]


def _rotate(q_wxyz: list[float], v: list[float]) -> list[float]:
    """Rotate a body vector into NED with the attitude quaternion."""
    w, x, y, z = q_wxyz
    vx, vy, vz = v
    return [
        (1 - 2 * (y * y + z * z)) * vx + 2 * (x * y - w * z) * vy + 2 * (x * z + w * y) * vz,
        2 * (x * y + w * z) * vx + (1 - 2 * (x * x + z * z)) * vy + 2 * (y * z - w * x) * vz,
        2 * (x * z - w * y) * vx + 2 * (y * z + w * x) * vy + (1 - 2 * (x * x + y * y)) * vz,
    ]


def _yaw_only(q_wxyz: list[float]) -> list[float]:
    w, x, y, z = q_wxyz
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return [math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)]


def _all_nan(v: list[float]) -> bool:
    return all(math.isnan(c) for c in v)


class Receiver:
    def __init__(self, vehicle: SimVehicle) -> None:
        self._v = vehicle
        self._handlers: dict[int, Callable[[Link, Message], None]] = {
            mavlink.MAVLINK_MSG_ID_HEARTBEAT: self._on_heartbeat,
            mavlink.MAVLINK_MSG_ID_COMMAND_LONG: self._on_command_long,
            mavlink.MAVLINK_MSG_ID_COMMAND_INT: self._on_command_int,
            mavlink.MAVLINK_MSG_ID_SET_MODE: self._on_set_mode,
            mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED: self._on_local_ned,
            mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT: self._on_global_int,
            mavlink.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET: self._on_attitude_target,
            mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_LIST: self._on_param_request_list,
            mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_READ: self._on_param_request_read,
            mavlink.MAVLINK_MSG_ID_PARAM_SET: self._on_param_set,
            mavlink.MAVLINK_MSG_ID_SET_GPS_GLOBAL_ORIGIN: self._on_set_gps_global_origin,
            mavlink.MAVLINK_MSG_ID_MISSION_REQUEST_LIST: self._on_mission_request_list,
        }
        self._commands: dict[int, Callable[[Command, Link], int | None]] = {
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm_disarm,
            mavlink.MAV_CMD_DO_SET_MODE: self._cmd_do_set_mode,
            mavlink.MAV_CMD_NAV_TAKEOFF: self._cmd_takeoff,
            mavlink.MAV_CMD_NAV_LAND: self._cmd_land,
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: self._cmd_rtl,
            mavlink.MAV_CMD_DO_REPOSITION: self._cmd_reposition,
            mavlink.MAV_CMD_DO_VTOL_TRANSITION: self._cmd_vtol_transition,
            mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_set_message_interval,
            mavlink.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_request_capabilities,
            mavlink.MAV_CMD_REQUEST_PROTOCOL_VERSION: self._cmd_request_protocol_version,
            mavlink.MAV_CMD_GET_HOME_POSITION: self._cmd_get_home_position,
            mavlink.MAV_CMD_DO_SET_HOME: self._cmd_set_home,
        }

    def handle(self, link: Link, msg: Message) -> None:
        handler = self._handlers.get(msg.get_msgId())
        if handler is not None:
            handler(link, msg)

    def _for_us(self, target_system: int, target_component: int) -> bool:
        return target_system == self._v.sysid and target_component in (self._v.compid, 0)

    def _on_heartbeat(self, link: Link, msg: Message) -> None:
        if msg.get_srcSystem() == self._v.sysid and msg.type != mavlink.MAV_TYPE_GCS:
            self._v.commander.on_heartbeat(is_gcs=False, now_s=self._v.now_s)
        elif msg.type == mavlink.MAV_TYPE_GCS:
            self._v.commander.on_heartbeat(is_gcs=True, now_s=self._v.now_s)

    # -- commands ----------------------------------------------------------------------

    def _on_command_long(self, link: Link, msg: Message) -> None:
        params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                  msg.param7]
        cmd = Command(msg.command, params, mavlink.MAV_FRAME_GLOBAL, False,
                      msg.get_srcSystem(), msg.get_srcComponent())
        self._dispatch(cmd, msg.target_system, msg.target_component, link)

    def _on_command_int(self, link: Link, msg: Message) -> None:
        lat = math.nan if msg.x == INT32_MAX else msg.x * 1e-7
        lon = math.nan if msg.y == INT32_MAX else msg.y * 1e-7
        params = [msg.param1, msg.param2, msg.param3, msg.param4, lat, lon, msg.z]
        cmd = Command(msg.command, params, msg.frame, True,
                      msg.get_srcSystem(), msg.get_srcComponent())
        self._dispatch(cmd, msg.target_system, msg.target_component, link)

    def _dispatch(self, cmd: Command, target_system: int, target_component: int,
                  link: Link) -> None:
        if not self._for_us(target_system, target_component) and not (
            target_system == 0 and self._is_any_target(cmd)
        ):
            return
        handler = self._commands.get(cmd.command)
        result = MAV_RESULT_UNSUPPORTED if handler is None else handler(cmd, link)
        if result is not None:
            self.ack(link, cmd, result)

    @staticmethod
    def _is_any_target(cmd: Command) -> bool:
        if cmd.command in _ANY_TARGET_COMMANDS:
            return True
        requested = _as_int(cmd.params[0])
        return cmd.command == mavlink.MAV_CMD_REQUEST_MESSAGE and requested in _VERSION_MESSAGES

    def ack(self, link: Link, cmd: Command, result: int) -> None:
        link.send(mavlink.MAVLink_command_ack_message(
            cmd.command, result, 0, 0, cmd.source_system, cmd.source_component))

    def _cmd_arm_disarm(self, cmd: Command, link: Link) -> int | None:
        action = cmd.params[0]
        force = _as_int(cmd.params[1]) == ARM_DISARM_FORCE_MAGIC
        if action == 1.0:
            return self._v.commander.arm(self._v.now_s)
        if action == 0.0:
            return self._v.commander.disarm(force)
        return None  # PX4 leaves any other param1 unanswered

    def _cmd_do_set_mode(self, cmd: Command, link: Link) -> int | None:
        # PX4 v1.16 acks every DO_SET_MODE twice: ACCEPTED at once, then the real result.
        self.ack(link, cmd, MAV_RESULT_ACCEPTED)
        return self._set_mode(*(_as_int(p) for p in cmd.params[:3]))

    def _set_mode(self, base_mode: int, main_mode: int, sub_mode: int) -> int:
        if not base_mode & modes.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return MAV_RESULT_TEMPORARILY_REJECTED
        mode = Px4Mode(main_mode, sub_mode if main_mode in (modes.MainMode.AUTO,
                                                             modes.MainMode.POSCTL) else 0)
        return self._v.commander.request_mode(mode)

    def _on_set_mode(self, link: Link, msg: Message) -> None:
        if msg.target_system != self._v.sysid:
            return
        custom = modes.decode_custom_mode(msg.custom_mode)
        cmd = Command(mavlink.MAV_CMD_DO_SET_MODE, [float(msg.base_mode), float(custom.main),
                      float(custom.sub), 0, 0, 0, 0], 0, False,
                      msg.get_srcSystem(), msg.get_srcComponent())
        self.ack(link, cmd, MAV_RESULT_ACCEPTED)
        self.ack(link, cmd, self._set_mode(msg.base_mode, custom.main, custom.sub))

    def _cmd_takeoff(self, cmd: Command, link: Link) -> int:
        v = self._v
        if not v.ready or v.airframe_name == "rover":
            return MAV_RESULT_TEMPORARILY_REJECTED
        v.navigator.request_takeoff(cmd.params[6])
        return v.commander.request_mode(modes.AUTO_TAKEOFF)

    def _cmd_land(self, cmd: Command, link: Link) -> int:
        self._v.commander.switch_mode(modes.AUTO_LAND)
        return MAV_RESULT_ACCEPTED

    def _cmd_rtl(self, cmd: Command, link: Link) -> int:
        return self._v.commander.request_mode(modes.AUTO_RTL)

    def _cmd_reposition(self, cmd: Command, link: Link) -> int:
        v = self._v
        speed, flags, _radius, yaw, lat, lon, alt = cmd.params
        if _as_int(flags) != MAV_DO_REPOSITION_FLAGS_CHANGE_MODE:
            return MAV_RESULT_UNSUPPORTED
        if not v.ready:
            return MAV_RESULT_TEMPORARILY_REJECTED
        current = v.truth.position_ned_m
        target = list(current)
        if math.isfinite(lat) and math.isfinite(lon):
            north, east, _ = v.origin.to_ned(lat, lon, v.origin.alt_m)
            target[0], target[1] = north, east
        if math.isfinite(alt):
            target[2] = self._down_of_alt(alt, cmd.frame)
        if not v.within_geofence(target):
            return MAV_RESULT_DENIED
        yaw_rad = yaw if math.isfinite(yaw) else math.nan
        speed_m_s = speed if math.isfinite(speed) and speed > 0 else math.nan
        v.navigator.request_reposition(target, yaw_rad, speed_m_s)
        v.commander.switch_mode(modes.AUTO_LOITER)
        return MAV_RESULT_ACCEPTED

    def _down_of_alt(self, alt_m: float, frame: int) -> float:
        """Local down of an altitude in a command's frame (AMSL unless relative)."""
        relative_frames = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                           mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
        if frame in relative_frames:
            return self._v.commander.home.position_ned_m[2] - alt_m
        return self._v.origin.down_of_altitude(alt_m)

    def _cmd_vtol_transition(self, cmd: Command, link: Link) -> int | None:
        v = self._v
        if not v.model.is_vtol:
            return None  # PX4 without a VTOL attitude controller leaves it unanswered
        state = _as_int(cmd.params[0])
        immediate = _as_int(cmd.params[1]) == 1
        if state == VTOL_TRANSITION_FW:
            if v.commander.nav_mode in _NO_FRONT_TRANSITION_MODES:
                return MAV_RESULT_TEMPORARILY_REJECTED
            v.model.request_transition(to_fixed_wing=True, immediate=immediate)
            return MAV_RESULT_ACCEPTED
        if state == VTOL_TRANSITION_MC:
            v.model.request_transition(to_fixed_wing=False, immediate=immediate)
            return MAV_RESULT_ACCEPTED
        return MAV_RESULT_DENIED

    def _cmd_set_message_interval(self, cmd: Command, link: Link) -> int:
        streams = self._v.streams_of(link)
        ok = streams.set_interval(_as_int(cmd.params[0]), cmd.params[1], self._v.now_s)
        return MAV_RESULT_ACCEPTED if ok else MAV_RESULT_FAILED

    def _cmd_request_message(self, cmd: Command, link: Link) -> int | None:
        msg = self._v.messages.build(_as_int(cmd.params[0]))
        if msg is None:
            return MAV_RESULT_FAILED
        self.ack(link, cmd, MAV_RESULT_ACCEPTED)
        link.send(msg)
        return None

    def _reply_with(self, cmd: Command, link: Link, msg_id: int) -> None:
        msg = self._v.messages.build(msg_id)
        self.ack(link, cmd, MAV_RESULT_ACCEPTED if msg is not None else MAV_RESULT_FAILED)
        if msg is not None:
            link.send(msg)

    def _cmd_request_capabilities(self, cmd: Command, link: Link) -> None:
        self._reply_with(cmd, link, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)

    def _cmd_request_protocol_version(self, cmd: Command, link: Link) -> None:
        self._reply_with(cmd, link, MAVLINK_MSG_ID_PROTOCOL_VERSION)

    def _cmd_get_home_position(self, cmd: Command, link: Link) -> None:
        self._reply_with(cmd, link, mavlink.MAVLINK_MSG_ID_HOME_POSITION)

    def _cmd_set_home(self, cmd: Command, link: Link) -> int:
        v = self._v
        if not v.ready:
            return MAV_RESULT_TEMPORARILY_REJECTED
        if cmd.params[0] == 1.0:
            v.set_home_here()
        else:
            lat, lon, alt = cmd.params[4], cmd.params[5], cmd.params[6]
            if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(alt)):
                return MAV_RESULT_DENIED
            # PX4 takes any finite point; one off the globe or beyond what HOME_POSITION
            # carries would have no place in the local frame, so it is refused with a reason
            if not is_valid_lat_lon(lat, lon) or abs(alt) > MAVLINK_ALT_LIMIT_M:
                v.announce(MAV_SEVERITY_CRITICAL,
                           f"Home not set: {lat:.7f}, {lon:.7f}, {alt:.1f} m out of range")
                return MAV_RESULT_DENIED
            # PX4's commander: param4 is the home yaw in degrees, NaN keeps it
            v.set_home_at(lat, lon, alt, math.radians(cmd.params[3]))
        return MAV_RESULT_ACCEPTED

    # -- offboard setpoints ------------------------------------------------------------

    def _refuse(self, message_name: str, reason: str) -> None:
        self._v.announce(MAV_SEVERITY_CRITICAL, f"{message_name} {reason}")

    def _accept(self, setpoint: ControlSetpoint) -> None:
        self._v.commander.on_offboard_setpoint(setpoint, self._v.now_s)

    def _on_local_ned(self, link: Link, msg: Message) -> None:
        if not self._for_us(msg.target_system, msg.target_component):
            return
        name = "SET_POSITION_TARGET_LOCAL_NED"
        frame = msg.coordinate_frame
        if frame not in (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_NED):
            self._refuse(name, f"coordinate frame {frame} unsupported")
            return
        mask = msg.type_mask
        position = _vector(mask, (IGNORE_PX, IGNORE_PY, IGNORE_PZ), (msg.x, msg.y, msg.z))
        velocity = _vector(mask, (IGNORE_VX, IGNORE_VY, IGNORE_VZ), (msg.vx, msg.vy, msg.vz))
        accel = _vector(mask, (IGNORE_AX, IGNORE_AY, IGNORE_AZ), (msg.afx, msg.afy, msg.afz))
        if frame == mavlink.MAV_FRAME_BODY_NED:
            q = self._v.truth.q_wxyz
            position = [math.nan] * 3
            velocity = _rotate(_yaw_only(q), velocity)
            accel = _rotate(q, accel)
        self._publish_trajectory(name, mask, position, velocity, accel, msg.yaw, msg.yaw_rate)

    def _on_global_int(self, link: Link, msg: Message) -> None:
        if not self._for_us(msg.target_system, msg.target_component):
            return
        name = "SET_POSITION_TARGET_GLOBAL_INT"
        frame = msg.coordinate_frame
        if frame not in (mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                         mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT):
            self._refuse(name, f"coordinate frame {frame} unsupported")
            return
        v = self._v
        if not v.ready:
            return  # no global position yet: PX4 drops these silently
        mask = msg.type_mask
        position = [math.nan] * 3
        if not mask & (IGNORE_PX | IGNORE_PY | IGNORE_PZ):
            north, east, _ = v.origin.to_ned(msg.lat_int * 1e-7, msg.lon_int * 1e-7, v.origin.alt_m)
            if frame == mavlink.MAV_FRAME_GLOBAL_INT:
                down = v.origin.down_of_altitude(msg.alt)
            elif frame == mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT:
                down = v.commander.home.position_ned_m[2] - msg.alt
            else:
                down = -msg.alt  # flat terrain at local down 0
            position = [north, east, down]
        velocity = _vector(mask, (IGNORE_VX, IGNORE_VY, IGNORE_VZ), (msg.vx, msg.vy, msg.vz))
        accel = _vector(mask, (IGNORE_AX, IGNORE_AY, IGNORE_AZ), (msg.afx, msg.afy, msg.afz))
        self._publish_trajectory(name, mask, position, velocity, accel, msg.yaw, msg.yaw_rate)

    def _publish_trajectory(self, name: str, mask: int, position: list[float],
                            velocity: list[float], accel: list[float],
                            yaw: float, yaw_rate: float) -> None:
        if not _all_nan(accel) and mask & FORCE_SET:
            self._refuse(name, "force not supported")
            return
        if _all_nan(position) and _all_nan(velocity) and _all_nan(accel):
            self._refuse(name, "invalid")
            return
        self._accept(TrajectorySetpoint(
            position_ned_m=position,
            velocity_ned_m_s=velocity,
            acceleration_ned_m_s2=accel,
            yaw_rad=_nan_if(bool(mask & IGNORE_YAW), yaw),
            yawspeed_rad_s=_nan_if(bool(mask & IGNORE_YAW_RATE), yaw_rate),
        ))

    def _on_attitude_target(self, link: Link, msg: Message) -> None:
        if not self._for_us(msg.target_system, msg.target_component):
            return
        mask = msg.type_mask
        rates_ignored = (mask & (IGNORE_ROLL_RATE | IGNORE_PITCH_RATE | IGNORE_YAW_RATE_BODY)
                         == IGNORE_ROLL_RATE | IGNORE_PITCH_RATE | IGNORE_YAW_RATE_BODY)
        attitude_ignored = bool(mask & IGNORE_ATTITUDE)
        if rates_ignored and attitude_ignored:
            self._refuse("SET_ATTITUDE_TARGET", "invalid")
            return
        throttle = self._v.params.get("MPC_THR_HOVER") if mask & IGNORE_THROTTLE else msg.thrust
        thrust = self._thrust_body(throttle)
        setpoint: ControlSetpoint
        if not rates_ignored:
            rates = _vector(mask, (IGNORE_ROLL_RATE, IGNORE_PITCH_RATE, IGNORE_YAW_RATE_BODY),
                            (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate))
            r = tuple(0.0 if math.isnan(c) else c for c in rates)
            setpoint = RatesSetpoint(rates_rad_s=(r[0], r[1], r[2]), thrust_body=thrust)
        else:
            q = msg.q
            setpoint = AttitudeSetpoint(q_wxyz=(q[0], q[1], q[2], q[3]), thrust_body=thrust)
        self._accept(setpoint)

    def _thrust_body(self, throttle: float) -> tuple[float, float, float]:
        """Multicopter thrust points along -z body, fixed wing along +x."""
        if self._v.model.in_fixed_wing_flight:
            return (throttle, 0.0, 0.0)
        return (0.0, 0.0, -throttle)

    # -- parameters --------------------------------------------------------------------

    def _param_value(self, name: str) -> Message:
        params = self._v.params
        return mavlink.MAVLink_param_value_message(
            name.encode(), params.wire_value(name), params.param_type(name), len(params),
            params.index(name))

    def _on_param_request_list(self, link: Link, msg: Message) -> None:
        if not self._for_us(msg.target_system, msg.target_component):
            return
        for name in self._v.params:
            link.send(self._param_value(name))

    def _on_param_request_read(self, link: Link, msg: Message) -> None:
        if not self._for_us(msg.target_system, msg.target_component):
            return
        params = self._v.params
        name: str | None = msg.param_id if msg.param_index < 0 else params.name_at(msg.param_index)
        if name is None or name not in params:
            return  # PX4 stays silent about parameters it does not have
        link.send(self._param_value(name))

    def _on_param_set(self, link: Link, msg: Message) -> None:
        if not self._for_us(msg.target_system, msg.target_component):
            return
        params = self._v.params
        name = msg.param_id
        if name not in params:
            return
        params.set_from_wire(name, msg.param_value)
        self._v.broadcast(self._param_value(name))

    # -- origin, missions --------------------------------------------------------------

    def _on_set_gps_global_origin(self, link: Link, msg: Message) -> None:
        if msg.target_system not in (self._v.sysid, 0):
            return
        lat, lon, alt = msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3
        if is_valid_lat_lon(lat, lon):
            self._v.set_origin(lat, lon, alt)
        else:
            # EKF2 refuses the origin (checkLatLonValidity) and logs it; the reply below
            # then shows the origin unchanged, as PX4's does
            self._v.announce(mavlink.MAV_SEVERITY_ERROR,
                             f"Failed to set new NED origin (LLA): {lat:.7f}, {lon:.7f}, {alt:.3f}")
        origin = self._v.messages.gps_global_origin()
        if origin is not None:
            self._v.broadcast(origin)

    def _on_mission_request_list(self, link: Link, msg: Message) -> None:
        if not self._for_us(msg.target_system, msg.target_component):
            return
        link.send(mavlink.MAVLink_mission_count_message(
            msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type))
