"""The channels of one link, by topic (docs/foxglove.md has the list):

- ``/vehicle_<sysid>/mavlink/<TYPE>``: every MAVLink message received from that system,
  its decoded fields as JSON; ``/vehicle_<sysid>/sent/<TYPE>``: every one sent to it (the
  setpoints among them); ``/gcs/sent/<TYPE>``: what is sent to every system (HEARTBEAT)
- ``/vehicle_<sysid>/state`` and ``/health``: the API's state and its stream and link figures
- ``/vehicle_<sysid>/log`` (foxglove.Log): status texts and the vehicle's events
- ``/vehicle_<sysid>/location`` (foxglove.LocationFix), ``/tf`` (foxglove.FrameTransform,
  ``map`` → ``vehicle_<sysid>``) and ``/pose`` (foxglove.PoseInFrame in ``map``): ``map``
  is ENU at the vehicle's local origin, the vehicle frame FLU, as Foxglove's 3D panel expects

A channel is made when its first message comes and is tagged with its link (metadata
``skyhelm.link``), which is how each link's MCAP file takes only its own channels.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import foxglove
from foxglove.channels import (
    FrameTransformChannel,
    LocationFixChannel,
    LogChannel,
    PoseInFrameChannel,
)
from pymavlink.dialects.v20 import development as mavlink

from server.foxglove.schemas import HEALTH_SCHEMA, STATE_SCHEMA, JsonSchema, mavlink_schema

LINK_METADATA = "skyhelm.link"
WORLD_FRAME = "map"
GCS_PREFIX = "/gcs"


def vehicle_prefix(sysid: int) -> str:
    return f"/vehicle_{sysid}"


def vehicle_frame(sysid: int) -> str:
    return f"vehicle_{sysid}"


def mavlink_topic(sysid: int, sent: bool, kind: str) -> str:
    if sent:
        prefix = vehicle_prefix(sysid) if sysid else GCS_PREFIX
        return f"{prefix}/sent/{kind}"
    return f"{vehicle_prefix(sysid)}/mavlink/{kind}"


class LinkChannels:
    """Channels of one link in a context, made on first use."""

    def __init__(self, context: foxglove.Context, link_label: str) -> None:
        self.context = context
        self.metadata = {LINK_METADATA: link_label}
        self._mavlink: dict[tuple[int, bool, str], foxglove.Channel] = {}
        self._vehicles: dict[int, VehicleChannels] = {}

    def mavlink(self, sysid: int, sent: bool, msg: mavlink.MAVLink_message) -> foxglove.Channel:
        key = (sysid, sent, msg.get_type())
        channel = self._mavlink.get(key)
        if channel is None:
            channel = self._mavlink[key] = self.json_channel(mavlink_topic(*key),
                                                             mavlink_schema(msg))
        return channel

    def json_channel(self, topic: str, schema: JsonSchema) -> foxglove.Channel:
        return foxglove.Channel(topic, schema=schema, context=self.context,
                                metadata=self.metadata)

    def vehicle(self, sysid: int) -> VehicleChannels:
        channels = self._vehicles.get(sysid)
        if channels is None:
            channels = self._vehicles[sysid] = VehicleChannels(sysid, self)
        return channels

    def close(self) -> None:
        for channel in self._mavlink.values():
            channel.close()
        for vehicle in self._vehicles.values():
            vehicle.close()


@dataclass
class Pose:
    """The newest local position (NED, m) and attitude (rad) a vehicle reported."""

    position_ned: tuple[float, float, float] | None = None
    attitude_rad: tuple[float, float, float] | None = None


@dataclass
class VehicleChannels:
    """One vehicle's channels other than its MAVLink messages."""

    sysid: int
    link: LinkChannels
    pose: Pose = field(default_factory=Pose)

    def __post_init__(self) -> None:
        prefix = vehicle_prefix(self.sysid)
        context, metadata = self.link.context, self.link.metadata
        self.frame = vehicle_frame(self.sysid)
        self.log = LogChannel(f"{prefix}/log", context=context, metadata=metadata)
        self.location = LocationFixChannel(f"{prefix}/location", context=context, metadata=metadata)
        self.transform = FrameTransformChannel(f"{prefix}/tf", context=context, metadata=metadata)
        self.pose_in_frame = PoseInFrameChannel(
            f"{prefix}/pose", context=context, metadata=metadata
        )
        self._live: dict[str, foxglove.Channel] = {}

    # live only (a .tlog holds neither): made when the bridge first asks
    @property
    def state(self) -> foxglove.Channel:
        return self._live_channel("state", STATE_SCHEMA)

    @property
    def health(self) -> foxglove.Channel:
        return self._live_channel("health", HEALTH_SCHEMA)

    def _live_channel(self, topic: str, schema: JsonSchema) -> foxglove.Channel:
        channel = self._live.get(topic)
        if channel is None:
            channel = self._live[topic] = self.link.json_channel(
                f"{vehicle_prefix(self.sysid)}/{topic}", schema
            )
        return channel

    def close(self) -> None:
        for typed in (self.log, self.location, self.transform, self.pose_in_frame):
            typed.close()
        for channel in self._live.values():
            channel.close()
