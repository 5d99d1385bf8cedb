"""What Foxglove's Map, 3D and Log panels read, derived from a vehicle's MAVLink messages:
GLOBAL_POSITION_INT → foxglove.LocationFix; each LOCAL_POSITION_NED with the latest
ATTITUDE → foxglove.FrameTransform and foxglove.PoseInFrame (NED/FRD turned into ENU/FLU);
STATUSTEXT (chunks joined) → foxglove.Log. Live and `skyhelm convert` both go through
here, so a recording and the live view show the same."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from foxglove.messages import (
    FrameTransform,
    LocationFix,
    Log,
    LogLevel,
    Pose,
    PoseInFrame,
    Quaternion,
    Timestamp,
    Vector3,
)

from server.foxglove.channels import WORLD_FRAME, VehicleChannels
from server.link.codec.statustext import StatusTextAssembler

MAV_COMP_ID_AUTOPILOT1 = 1
# MAV_SEVERITY 0..7 (EMERGENCY … DEBUG) as Foxglove's log levels
_LEVELS = (
    LogLevel.Fatal, LogLevel.Fatal, LogLevel.Fatal, LogLevel.Error,
    LogLevel.Warning, LogLevel.Info, LogLevel.Info, LogLevel.Debug,
)  # fmt: skip
LEVEL_BY_SEVERITY_NAME = dict(
    zip(("EMERGENCY", "ALERT", "CRITICAL", "ERROR", "WARNING", "NOTICE", "INFO", "DEBUG"),
        _LEVELS, strict=True)
)  # fmt: skip


def timestamp(time_ns: int) -> Timestamp:
    return Timestamp(time_ns // 1_000_000_000, time_ns % 1_000_000_000)


def enu_flu_quaternion(
    roll_rad: float, pitch_rad: float, yaw_rad: float
) -> tuple[float, float, float, float]:
    """The FRD body's attitude in NED as the FLU body's in ENU, (x, y, z, w): roll stays,
    pitch turns sign, yaw is measured from east counter-clockwise (90° − yaw)."""
    half_r, half_p, half_y = roll_rad / 2, -pitch_rad / 2, (math.pi / 2 - yaw_rad) / 2
    cr, sr = math.cos(half_r), math.sin(half_r)
    cp, sp = math.cos(half_p), math.sin(half_p)
    cy, sy = math.cos(half_y), math.sin(half_y)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


class Derived:
    """One vehicle's derived channels, fed its MAVLink messages; each message is only
    built when its channel has a reader (a client or an MCAP file)."""

    def __init__(self, channels: VehicleChannels) -> None:
        self.channels = channels
        self._now_s = 0.0
        self._texts = StatusTextAssembler(lambda: self._now_s)
        self.handlers: dict[str, Callable[[Any, int], None]] = {
            "GLOBAL_POSITION_INT": self._global_position,
            "LOCAL_POSITION_NED": self._local_position,
            "ATTITUDE": self._attitude,
            "STATUSTEXT": self._statustext,
        }

    def _global_position(self, msg: Any, time_ns: int) -> None:
        channel = self.channels.location
        if msg.get_srcComponent() != MAV_COMP_ID_AUTOPILOT1 or not channel.has_sinks():
            return
        channel.log(
            LocationFix(
                timestamp=timestamp(time_ns), frame_id=self.channels.frame,
                latitude=msg.lat / 1e7, longitude=msg.lon / 1e7, altitude=msg.alt / 1e3,
            ),
            log_time=time_ns,
        )

    def _local_position(self, msg: Any, time_ns: int) -> None:
        if msg.get_srcComponent() == MAV_COMP_ID_AUTOPILOT1:
            self.channels.pose.position_ned = (msg.x, msg.y, msg.z)
            self._pose(time_ns)

    def _attitude(self, msg: Any, time_ns: int) -> None:
        # kept for the next position: a pose per position report is the 3D view's rate, and
        # one per ATTITUDE too would double the work for no new place
        if msg.get_srcComponent() == MAV_COMP_ID_AUTOPILOT1:
            self.channels.pose.attitude_rad = (msg.roll, msg.pitch, msg.yaw)

    def _pose(self, time_ns: int) -> None:
        channels = self.channels
        position, attitude = channels.pose.position_ned, channels.pose.attitude_rad
        if position is None or attitude is None:
            return
        transform, pose = channels.transform.has_sinks(), channels.pose_in_frame.has_sinks()
        if not (transform or pose):
            return
        north_m, east_m, down_m = position
        stamp = timestamp(time_ns)
        translation = Vector3(x=east_m, y=north_m, z=-down_m)
        x, y, z, w = enu_flu_quaternion(*attitude)
        rotation = Quaternion(x=x, y=y, z=z, w=w)
        if transform:
            channels.transform.log(
                FrameTransform(
                    timestamp=stamp, parent_frame_id=WORLD_FRAME, child_frame_id=channels.frame,
                    translation=translation, rotation=rotation,
                ),
                log_time=time_ns,
            )
        if pose:
            channels.pose_in_frame.log(
                PoseInFrame(
                    timestamp=stamp, frame_id=WORLD_FRAME,
                    pose=Pose(
                        position=Vector3(x=east_m, y=north_m, z=-down_m),
                        orientation=Quaternion(x=x, y=y, z=z, w=w),
                    ),
                ),
                log_time=time_ns,
            )

    def _statustext(self, msg: Any, time_ns: int) -> None:
        self._now_s = time_ns / 1e9
        text = msg.text if isinstance(msg.text, str) else msg.text.decode("utf-8", "replace")
        for severity, whole in self._texts.feed(
            msg.severity, text.rstrip("\0"), getattr(msg, "id", 0), getattr(msg, "chunk_seq", 0)
        ):
            level = _LEVELS[severity] if 0 <= severity < len(_LEVELS) else LogLevel.Unknown
            self.log(level, whole, f"{self.channels.frame}.{msg.get_srcComponent()}", time_ns)

    def log(self, level: LogLevel, message: str, name: str, time_ns: int) -> None:
        channel = self.channels.log
        if channel.has_sinks():
            channel.log(
                Log(timestamp=timestamp(time_ns), level=level, message=message, name=name),
                log_time=time_ns,
            )
