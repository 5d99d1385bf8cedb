"""MAVLink input of the simulated vehicle, after PX4's mavlink_receiver.

Messages are dispatched by id: commands (COMMAND_LONG / COMMAND_INT / SET_MODE) are acked to
the sender and carried out by `sim.mavlink.vehicle_command`; offboard setpoints go to
`sim.mavlink.offboard_setpoints`; parameters to `sim.mavlink.mavlink_parameters`. What only
the MAVLink module answers itself (message intervals and requests, versions, origin,
missions) is here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

from pymavlink.dialects.v20 import development as mavlink

from sim.flight.commander import MAV_RESULT_ACCEPTED, MAV_RESULT_FAILED, MAV_RESULT_UNSUPPORTED
from sim.flight.manual_control import SOURCE_MAVLINK_0, stick_sample
from sim.lib import modes
from sim.lib.geo import is_valid_lat_lon
from sim.mavlink.mavlink_event_services import EventServices
from sim.mavlink.mavlink_messages import MAVLINK_MSG_ID_PROTOCOL_VERSION, MessageFactory
from sim.mavlink.mavlink_parameters import MavlinkParameters
from sim.mavlink.offboard_setpoints import OffboardSetpoints
from sim.mavlink.streams import StreamSet
from sim.mavlink.vehicle_command import (
    Command,
    CommandHandler,
    VehicleCommands,
    as_int,
    command_ack,
)
from sim.mavlink.vehicle_interface import Link, Message, VehicleInterface

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
# Messages taken only when addressed to this vehicle (target component 0 = any).
_TARGETED_MESSAGES = frozenset(
    {
        mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED,
        mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT,
        mavlink.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET,
        mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_LIST,
        mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_READ,
        mavlink.MAVLINK_MSG_ID_PARAM_SET,
        mavlink.MAVLINK_MSG_ID_MISSION_REQUEST_LIST,
    }
)


class ManualControlReceiver:
    """MANUAL_CONTROL in: each link is its own MAVLink instance (SOURCE_MAVLINK_0 + i)."""

    def __init__(self, vehicle: VehicleInterface) -> None:
        self._v = vehicle
        self._instances: dict[int, int] = {}

    def handle(self, link: object, msg: Message) -> None:
        if msg.target not in (0, self._v.sysid):
            return
        instance = self._instances.setdefault(id(link), len(self._instances))
        now = self._v.now_s
        sample = stick_sample(msg.x, msg.y, msg.z, msg.r, now, SOURCE_MAVLINK_0 + instance)
        self._v.commander.on_manual_control(sample, now)


class ReceiverVehicle(VehicleInterface, Protocol):
    """The vehicle plus its telemetry, which requests and interval changes reach."""

    messages: MessageFactory

    def streams_of(self, link: Link) -> StreamSet: ...


class Receiver:
    def __init__(self, vehicle: ReceiverVehicle) -> None:
        self._v = vehicle
        self._vehicle_commands = VehicleCommands(vehicle)
        setpoints = OffboardSetpoints(vehicle)
        parameters = MavlinkParameters(vehicle.params, vehicle.broadcast)
        self._event_services = EventServices(vehicle)
        self._handlers: dict[int, Callable[[Link, Message], None]] = {
            mavlink.MAVLINK_MSG_ID_HEARTBEAT: self._on_heartbeat,
            mavlink.MAVLINK_MSG_ID_COMMAND_LONG: self._on_command_long,
            mavlink.MAVLINK_MSG_ID_COMMAND_INT: self._on_command_int,
            mavlink.MAVLINK_MSG_ID_SET_MODE: self._on_set_mode,
            mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED: setpoints.handle_local_ned,
            mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT: setpoints.handle_global_int,
            mavlink.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET: setpoints.handle_attitude_target,
            mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_LIST: parameters.handle_request_list,
            mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_READ: parameters.handle_request_read,
            mavlink.MAVLINK_MSG_ID_PARAM_SET: parameters.handle_set,
            mavlink.MAVLINK_MSG_ID_SET_GPS_GLOBAL_ORIGIN: self._on_set_gps_global_origin,
            mavlink.MAVLINK_MSG_ID_MISSION_REQUEST_LIST: self._on_mission_request_list,
            mavlink.MAVLINK_MSG_ID_TIMESYNC: self._on_timesync,
            mavlink.MAVLINK_MSG_ID_MANUAL_CONTROL: ManualControlReceiver(vehicle).handle,
            mavlink.MAVLINK_MSG_ID_FILE_TRANSFER_PROTOCOL: self._event_services.handle_ftp,
            mavlink.MAVLINK_MSG_ID_UNKNOWN: self._event_services.handle_unknown,
        }
        self._commands: dict[int, CommandHandler] = {
            **self._vehicle_commands.handlers,
            mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_set_message_interval,
            mavlink.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_message_interval,
            mavlink.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_request_capabilities,
            mavlink.MAV_CMD_REQUEST_PROTOCOL_VERSION: self._cmd_request_protocol_version,
            mavlink.MAV_CMD_GET_HOME_POSITION: self._cmd_get_home_position,
        }

    def handle(self, link: Link, msg: Message) -> None:
        msg_id = msg.get_msgId()
        handler = self._handlers.get(msg_id)
        if handler is None:
            return
        if msg_id in _TARGETED_MESSAGES and not self._for_us(msg.target_system,
                                                             msg.target_component):
            return
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
            link.send(command_ack(cmd, result))

    @staticmethod
    def _is_any_target(cmd: Command) -> bool:
        if cmd.command in _ANY_TARGET_COMMANDS:
            return True
        requested = as_int(cmd.params[0])
        return cmd.command == mavlink.MAV_CMD_REQUEST_MESSAGE and requested in _VERSION_MESSAGES

    def _on_set_mode(self, link: Link, msg: Message) -> None:
        if msg.target_system != self._v.sysid:
            return
        custom = modes.decode_custom_mode(msg.custom_mode)
        cmd = Command(mavlink.MAV_CMD_DO_SET_MODE, [float(msg.base_mode), float(custom.main),
                      float(custom.sub), 0, 0, 0, 0], 0, False,
                      msg.get_srcSystem(), msg.get_srcComponent())
        link.send(command_ack(cmd, MAV_RESULT_ACCEPTED))
        result = self._vehicle_commands.set_mode(msg.base_mode, custom.main, custom.sub)
        link.send(command_ack(cmd, result))

    def _cmd_set_message_interval(self, cmd: Command, link: Link) -> int:
        streams = self._v.streams_of(link)
        ok = streams.set_interval(as_int(cmd.params[0]), cmd.params[1], self._v.now_s)
        return MAV_RESULT_ACCEPTED if ok else MAV_RESULT_FAILED

    def _cmd_get_message_interval(self, cmd: Command, link: Link) -> int:
        # PX4 answers with MESSAGE_INTERVAL (0 µs: not streamed on this link), then the ack
        msg_id = as_int(cmd.params[0])
        interval_s = self._v.streams_of(link).interval_s(msg_id)
        interval_us = 0 if interval_s is None else round(interval_s * 1e6)
        link.send(mavlink.MAVLink_message_interval_message(msg_id, interval_us))
        return MAV_RESULT_ACCEPTED

    def _cmd_request_message(self, cmd: Command, link: Link) -> int | None:
        msg_id = as_int(cmd.params[0])
        msg = self._event_services.build(msg_id) or self._v.messages.build(msg_id)
        if msg is None:
            return MAV_RESULT_FAILED
        link.send(command_ack(cmd, MAV_RESULT_ACCEPTED))
        link.send(msg)
        return None

    def _reply_with(self, cmd: Command, link: Link, msg_id: int) -> None:
        msg = self._v.messages.build(msg_id)
        link.send(command_ack(cmd, MAV_RESULT_ACCEPTED if msg is not None else MAV_RESULT_FAILED))
        if msg is not None:
            link.send(msg)

    def _cmd_request_capabilities(self, cmd: Command, link: Link) -> None:
        self._reply_with(cmd, link, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)

    def _cmd_request_protocol_version(self, cmd: Command, link: Link) -> None:
        self._reply_with(cmd, link, MAVLINK_MSG_ID_PROTOCOL_VERSION)

    def _cmd_get_home_position(self, cmd: Command, link: Link) -> None:
        self._reply_with(cmd, link, mavlink.MAVLINK_MSG_ID_HOME_POSITION)

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

    def _on_timesync(self, link: Link, msg: Message) -> None:
        # a request (tc1 = 0) is answered with this clock in tc1 and the asker's ts1, as
        # PX4's timesync does; answers to the vehicle's own requests need nothing
        if msg.tc1 == 0:
            link.send(mavlink.MAVLink_timesync_message(int(self._v.now_s * 1e9), msg.ts1))

    def _on_mission_request_list(self, link: Link, msg: Message) -> None:
        link.send(mavlink.MAVLink_mission_count_message(
            msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type))
