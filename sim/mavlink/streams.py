"""Telemetry streams of the simulated vehicle: per-link message rates.

Each link (onboard/API, normal/GCS) has its own set of streams at the rates PX4 v1.16 SITL
runs them (mavlink_main.cpp's configure_streams for the ONBOARD and NORMAL modes, plus the
rates SITL's start script raises on the GCS link), changed by SET_MESSAGE_INTERVAL.
Messages (`sim.mavlink.mavlink_messages`) are built only when a stream is due and the link has
someone to send to, and once per sim time for all links.

Faster than real time (a fast-forward), every stream keeps its rate in sim time up to
FAST_FORWARD_CAP_HZ of wall time (or its own rate, if faster): at 8x the 30 Hz
LOCAL_POSITION_NED goes out 50 times per wall second, not 240. What a ground station reads
per wall second stays what a real PX4 link sends (SITL's GCS link streams attitude and
positions at 50 Hz), so a fast sim floods neither its peer nor a busy machine.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

from pymavlink.dialects.v20 import development as mavlink

from sim.lib.mavlink_custom import (
    MAVLINK_MSG_ID_LINK_NODE_STATUS,
    MAVLINK_MSG_ID_TIME_ESTIMATE_TO_TARGET,
)
from sim.mavlink.mavlink_messages import MessageFactory
from sim.mavlink.vehicle_interface import Message

_M = mavlink
# the most a stream is sent per wall second faster than real time (unless its own rate is
# more): PX4 v1.16 SITL's GCS link rate for attitude, positions and targets
FAST_FORWARD_CAP_HZ = 50.0
# streamed only while the fixed-wing position controller runs (a plane; a VTOL in FW)
FIXED_WING_ONLY = frozenset({_M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT})
# PX4 v1.16 SITL's onboard link (mavlink_main.cpp configure_streams, MAVLINK_MODE_ONBOARD),
# as measured by a census of a SIH quad (../shared/PX4_NOTES.md)
ONBOARD_RATES_HZ: dict[int, float] = {
    _M.MAVLINK_MSG_ID_ATTITUDE: 100.0,
    _M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 50.0,
    _M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 50.0,
    _M.MAVLINK_MSG_ID_HIGHRES_IMU: 50.0,
    _M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 30.0,
    _M.MAVLINK_MSG_ID_ODOMETRY: 30.0,
    _M.MAVLINK_MSG_ID_ALTITUDE: 10.0,
    _M.MAVLINK_MSG_ID_ATTITUDE_TARGET: 10.0,
    _M.MAVLINK_MSG_ID_DISTANCE_SENSOR: 10.0,
    _M.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 10.0,
    _M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 10.0,
    _M.MAVLINK_MSG_ID_TIMESYNC: 10.0,
    _M.MAVLINK_MSG_ID_VFR_HUD: 10.0,
    _M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT: 10.0,
    _M.MAVLINK_MSG_ID_GPS_RAW_INT: 8.0,
    _M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0,
    _M.MAVLINK_MSG_ID_SYS_STATUS: 5.0,
    _M.MAVLINK_MSG_ID_ESTIMATOR_STATUS: 1.0,
    _M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    _M.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    _M.MAVLINK_MSG_ID_OPEN_DRONE_ID_LOCATION: 1.0,
    _M.MAVLINK_MSG_ID_OPEN_DRONE_ID_SYSTEM: 1.0,
    _M.MAVLINK_MSG_ID_PING: 1.0,
    _M.MAVLINK_MSG_ID_SCALED_PRESSURE: 1.0,
    _M.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
    MAVLINK_MSG_ID_LINK_NODE_STATUS: 1.0,
    _M.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    _M.MAVLINK_MSG_ID_CURRENT_MODE: 0.5,
    _M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    _M.MAVLINK_MSG_ID_VIBRATION: 0.5,
    MAVLINK_MSG_ID_TIME_ESTIMATE_TO_TARGET: 0.5,
}

# PX4 v1.16 SITL's GCS link: MAVLINK_MODE_NORMAL with the streams px4-rc.mavlink raises
# for SITL (50 Hz attitude, positions, targets and outputs), as measured by a census
NORMAL_RATES_HZ: dict[int, float] = {
    _M.MAVLINK_MSG_ID_ATTITUDE: 50.0,
    _M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 50.0,
    _M.MAVLINK_MSG_ID_ATTITUDE_TARGET: 50.0,
    _M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 50.0,
    _M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 50.0,
    _M.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 50.0,
    _M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 50.0,
    _M.MAVLINK_MSG_ID_GPS_RAW_INT: 5.0,
    _M.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    _M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    _M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    _M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    _M.MAVLINK_MSG_ID_ALTITUDE: 1.0,
    _M.MAVLINK_MSG_ID_SCALED_PRESSURE: 1.0,
    _M.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    _M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT: 1.0,
    _M.MAVLINK_MSG_ID_OPEN_DRONE_ID_LOCATION: 1.0,
    _M.MAVLINK_MSG_ID_OPEN_DRONE_ID_SYSTEM: 1.0,
    MAVLINK_MSG_ID_LINK_NODE_STATUS: 1.0,
    _M.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    _M.MAVLINK_MSG_ID_CURRENT_MODE: 0.5,
    _M.MAVLINK_MSG_ID_DISTANCE_SENSOR: 0.5,
    MAVLINK_MSG_ID_TIME_ESTIMATE_TO_TARGET: 0.5,
    _M.MAVLINK_MSG_ID_ESTIMATOR_STATUS: 0.5,
    _M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    _M.MAVLINK_MSG_ID_PING: 0.1,
    _M.MAVLINK_MSG_ID_VIBRATION: 0.1,
}


class MessageSink(Protocol):
    """A link as the streams see it."""

    @property
    def has_remote(self) -> bool: ...

    def send(self, msg: Message) -> None: ...


class StreamSet:
    """The streams of one link: interval per message id, sent on sim-time deadlines."""

    def __init__(self, defaults_hz: dict[int, float], factory: MessageFactory) -> None:
        self._defaults_hz = dict(defaults_hz)
        self._factory = factory
        self._interval_s: dict[int, float] = {
            msg_id: 1.0 / hz for msg_id, hz in defaults_hz.items() if hz > 0
        }
        self._due_s: dict[int, float] = dict.fromkeys(self._interval_s, 0.0)
        self._next_due_s = 0.0

    def interval_s(self, msg_id: int) -> float | None:
        return self._interval_s.get(msg_id)

    def set_interval(self, msg_id: int, interval_us: float, now_s: float) -> bool:
        """SET_MESSAGE_INTERVAL; False (→ FAILED) for HEARTBEAT and unknown messages."""
        if msg_id == mavlink.MAVLINK_MSG_ID_HEARTBEAT or msg_id not in self._factory.builders:
            return False
        if interval_us < 0:
            self._interval_s.pop(msg_id, None)
            self._due_s.pop(msg_id, None)
        elif interval_us == 0:
            hz = self._defaults_hz.get(msg_id, 0.0)
            if hz > 0:
                self._interval_s[msg_id] = 1.0 / hz
                self._due_s[msg_id] = now_s
            else:
                self._interval_s.pop(msg_id, None)
                self._due_s.pop(msg_id, None)
        else:
            self._interval_s[msg_id] = interval_us / 1e6
            self._due_s[msg_id] = now_s
        self._next_due_s = min(self._due_s.values(), default=math.inf)
        return True

    def tick(self, now_s: float, sink: MessageSink, wall_speed: Callable[[], float]) -> None:
        """Send what is due at sim time ``now_s``; ``wall_speed()`` is sim seconds per wall
        second (above 1, streams are capped at FAST_FORWARD_CAP_HZ of wall time), asked
        only when something is due."""
        if now_s < self._next_due_s:
            return
        speed = wall_speed()
        send = sink.has_remote
        next_due = math.inf
        for msg_id, due in self._due_s.items():
            if now_s >= due:
                interval = self._interval_s[msg_id]
                if speed > 1.0:
                    interval = max(interval, speed * min(interval, 1.0 / FAST_FORWARD_CAP_HZ))
                # Keep the phase of the deadline; skip missed slots instead of bursting.
                due += interval
                if due <= now_s:
                    due = now_s + interval
                self._due_s[msg_id] = due
                if send:
                    msg = self._factory.build_streamed(msg_id)
                    if msg is not None:
                        sink.send(msg)
            next_due = min(next_due, due)
        self._next_due_s = next_due
