"""Asking a vehicle for the telemetry the dashboard needs, on every (re)connection, and
noting which requests it refused."""

from __future__ import annotations

import asyncio
from collections.abc import Mapping

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.aio import cancel_and_wait
from server.link.codec.commands import CommandResult
from server.link.core.vehicle_core import VehicleCore
from server.link.plugins.telemetry import Telemetry

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512

# A rate of 0: the stream is asked off (PX4: an interval < 0 stops it).
STREAM_OFF = 0.0
SET_MESSAGE_INTERVAL_STOP_US = -1.0

# What the dashboard needs, in Hz. CURRENT_MODE at >= 5 Hz because HEARTBEAT (1 Hz) shows
# failsafe mode changes late.
DEFAULT_TELEMETRY_RATES_HZ: Mapping[int, float] = {
    mavlink.MAVLINK_MSG_ID_CURRENT_MODE: 5.0,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: 1.0,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 20.0,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 20.0,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
    mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 5.0,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 2.0,
    mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 5.0,
    # PX4's onboard link streams these at 10-50 Hz and nothing here reads them: asked off
    # (SET_MESSAGE_INTERVAL -1), they cost neither the vehicle nor this server, which with
    # 50 vehicles spent about two thirds of its time taking in ~250 datagrams/s per vehicle.
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: STREAM_OFF,
    mavlink.MAVLINK_MSG_ID_HIGHRES_IMU: STREAM_OFF,
    mavlink.MAVLINK_MSG_ID_ODOMETRY: STREAM_OFF,
    mavlink.MAVLINK_MSG_ID_ATTITUDE_TARGET: STREAM_OFF,
    mavlink.MAVLINK_MSG_ID_ALTITUDE: STREAM_OFF,
    mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR: STREAM_OFF,
    mavlink.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT: STREAM_OFF,
}
# Requested once per connection: their values do not change often enough to stream.
ONE_SHOT_RETRIES = 30
ONE_SHOT_RETRY_INTERVAL_S = 1.0
ONE_SHOT_MESSAGES = (mavlink.MAVLINK_MSG_ID_HOME_POSITION, mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)


class TelemetryRequests:
    """SET_MESSAGE_INTERVAL for each streamed message, REQUEST_MESSAGE for home and origin."""

    def __init__(
        self,
        core: VehicleCore,
        telemetry: Telemetry,
        rates_hz: Mapping[int, float] | None = None,
    ) -> None:
        self._core = core
        self._telemetry = telemetry
        self._rates_hz = DEFAULT_TELEMETRY_RATES_HZ if rates_hz is None else rates_hz
        self._task: asyncio.Task[None] | None = None
        self.refused: dict[str, str] = {}  # message name -> outcome of its last request
        core.on_connection(self._connection_changed)
        self.start()

    def start(self, *, heartbeat_first: bool = False) -> None:
        """Ask for every stream (again: a vehicle that rebooted forgot them). After a loss,
        ``heartbeat_first`` asks for a HEARTBEAT at once: mode and arming are then known
        again within a round trip, not at the vehicle's next 1 Hz HEARTBEAT."""
        if not self._rates_hz:
            return
        if self._task is not None and not self._task.done():
            self._task.cancel()
        self._task = asyncio.get_running_loop().create_task(
            self._request_all(heartbeat_first), name=f"telemetry-request:{self._core.sysid}"
        )

    async def close(self) -> None:
        await cancel_and_wait(self._task)

    def _connection_changed(self, connected: bool) -> None:
        if connected:
            self.start(heartbeat_first=True)

    async def _request_all(self, heartbeat_first: bool = False) -> None:
        if heartbeat_first:
            await self._ask(MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HEARTBEAT)
        for msg_id, rate_hz in self._rates_hz.items():
            interval_us = 1e6 / rate_hz if rate_hz > 0 else SET_MESSAGE_INTERVAL_STOP_US
            self._note(msg_id, await self._ask(MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval_us))
        for msg_id in ONE_SHOT_MESSAGES:
            self._note(msg_id, await self._ask(MAV_CMD_REQUEST_MESSAGE, msg_id))
        # PX4 has no home or origin until its estimator has a position, which can come
        # seconds after the first heartbeat: ask again until both are known.
        for _ in range(ONE_SHOT_RETRIES):
            missing = self._missing_one_shots()
            self._clear_arrived(missing)
            if not missing or not self._core.connected:
                return
            await asyncio.sleep(ONE_SHOT_RETRY_INTERVAL_S)
            for msg_id in missing:
                self._note(msg_id, await self._ask(MAV_CMD_REQUEST_MESSAGE, msg_id))

    async def _ask(self, command: int, *params: float) -> CommandResult:
        return await self._core.requests.command_long(command, *params)

    def _missing_one_shots(self) -> list[int]:
        missing = []
        if self._telemetry.home is None:
            missing.append(mavlink.MAVLINK_MSG_ID_HOME_POSITION)
        if self._telemetry.origin is None:
            missing.append(mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
        return missing

    def _clear_arrived(self, missing: list[int]) -> None:
        """A one-shot message that came anyway (streamed, or answering an earlier request)
        is no longer refused, whatever its last request's outcome was."""
        for msg_id in ONE_SHOT_MESSAGES:
            if msg_id not in missing:
                self.refused.pop(_name(msg_id), None)

    def _note(self, msg_id: int, result: CommandResult) -> None:
        name = _name(msg_id)
        if result.ok:
            self.refused.pop(name, None)
            return
        self.refused[name] = result.outcome.value
        self._core.publish_event("stream", {"message": name, "outcome": result.outcome.value})


def _name(msg_id: int) -> str:
    msg_class = mavlink.mavlink_map.get(msg_id)
    return msg_class.msgname if msg_class is not None else str(msg_id)
