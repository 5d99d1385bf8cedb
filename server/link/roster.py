"""The vehicles of one link: discovered by HEARTBEAT, kept alive by any valid frame, judged
lost on silence (server.link.core.liveness), announced to subscribers as they appear."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec import px4_messages
from server.link.core.liveness import Liveness
from server.link.vehicle import Vehicle

log = logging.getLogger(__name__)

MAV_COMP_ID_AUTOPILOT1 = mavlink.MAV_COMP_ID_AUTOPILOT1
MAV_AUTOPILOT_INVALID = mavlink.MAV_AUTOPILOT_INVALID
# Heartbeats of these types are other ground stations or companions, never vehicles.
_NOT_VEHICLE_TYPES = frozenset({mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER})
# While frames wait unread, a vehicle is not judged silent for up to this long.
MAX_VERDICT_DELAY_S = 1.0
# subscribe() queues hold this many announcements and drop the oldest beyond it.
VEHICLE_QUEUE_SIZE = 32

# Makes the Vehicle for a system id from its first HEARTBEAT.
VehicleMaker = Callable[[int, mavlink.MAVLink_message], Vehicle]


class VehicleRoster:
    """Who is on the link and who is heard: every call runs on the link's event loop."""

    def __init__(self, link_name: str, liveness: Liveness, make_vehicle: VehicleMaker) -> None:
        self._link_name = link_name
        self.liveness = liveness
        self._make_vehicle = make_vehicle
        self._vehicles: dict[int, Vehicle] = {}
        self._connected: set[int] = set()
        self._queues: list[asyncio.Queue[Vehicle]] = []
        self.last_heartbeat_s: float | None = None
        # since when the loop has been behind reading the link (frames waiting)
        self._behind_since_s: float | None = None

    @property
    def vehicles(self) -> Mapping[int, Vehicle]:
        return MappingProxyType(self._vehicles)

    @property
    def any_connected(self) -> bool:
        return bool(self._connected)

    def subscribe(self) -> asyncio.Queue[Vehicle]:
        """A bounded queue of vehicles as they are discovered (already known ones first);
        a reader that falls behind loses the oldest announcements."""
        queue: asyncio.Queue[Vehicle] = asyncio.Queue(maxsize=VEHICLE_QUEUE_SIZE)
        for vehicle in self._vehicles.values():
            _put_drop_oldest(queue, vehicle)
        self._queues.append(queue)
        return queue

    def unsubscribe(self, queue: asyncio.Queue[Vehicle]) -> None:
        with contextlib.suppress(ValueError):
            self._queues.remove(queue)

    def frame_received(self, msg: mavlink.MAVLink_message, missing: int, now_s: float) -> None:
        """A valid frame from anyone; ``missing`` frames were skipped in its sequence."""
        if msg.get_srcComponent() != MAV_COMP_ID_AUTOPILOT1:
            return
        if msg.get_msgId() == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            self._heartbeat(msg, now_s)
        sysid = msg.get_srcSystem()
        self._heard(sysid, missing, now_s)
        if msg.get_msgId() == px4_messages.MAVLINK_MSG_ID_LINK_NODE_STATUS:
            self.liveness.node_status(sysid, now_s, msg.messages_received, msg.messages_lost)

    def _heartbeat(self, msg: mavlink.MAVLink_message, now_s: float) -> None:
        if msg.autopilot == MAV_AUTOPILOT_INVALID or msg.type in _NOT_VEHICLE_TYPES:
            return
        sysid = msg.get_srcSystem()
        self.liveness.heartbeat(sysid, now_s)
        self.last_heartbeat_s = now_s
        if sysid not in self._vehicles:
            self._discover(sysid, msg)

    def _heard(self, sysid: int, missing: int, now_s: float) -> None:
        """Any frame of a known vehicle keeps it alive, and brings a lost one back (its
        first frame after a cut is seldom the HEARTBEAT)."""
        if not self.liveness.known(sysid):
            return
        self.liveness.frame(sysid, now_s, missing)
        vehicle = self._vehicles.get(sysid)
        if vehicle is not None and sysid not in self._connected:
            self._connected.add(sysid)
            self.liveness.back(sysid, now_s)
            log.info("link %s: vehicle %d back", self._link_name, sysid)
            vehicle.set_connected(True)

    def _discover(self, sysid: int, heartbeat: mavlink.MAVLink_message) -> None:
        vehicle = self._make_vehicle(sysid, heartbeat)
        self._vehicles[sysid] = vehicle
        self._connected.add(sysid)
        log.info("link %s: vehicle %d discovered (type %d, autopilot %d)", self._link_name,
                 sysid, heartbeat.type, heartbeat.autopilot)
        for queue in self._queues:
            _put_drop_oldest(queue, vehicle)

    def judge(self, now_s: float, input_pending: bool) -> None:
        """Refresh every vehicle's link quality and mark the silent ones lost."""
        if input_pending:
            # Frames wait unread: the loop is behind, and a vehicle whose heartbeat is
            # queued is not silent. The verdict waits for the reads, but not for ever (a
            # flood must not hide a vehicle that really went quiet).
            if self._behind_since_s is None:
                self._behind_since_s = now_s
            if now_s - self._behind_since_s < MAX_VERDICT_DELAY_S:
                return
        else:
            self._behind_since_s = None
        for sysid, vehicle in self._vehicles.items():
            set_quality = getattr(vehicle, "set_link_quality", None)
            if set_quality is not None:  # test stand-ins may lack it
                set_quality(self.liveness.quality(sysid, now_s))
        for sysid in list(self._connected):
            why = self.liveness.silent_for(sysid, now_s)
            if why is not None:
                self._lose(sysid, why)

    def lose_all(self, reason: str) -> None:
        """Every vehicle heard is lost now, for ``reason`` (its peer is known gone): no
        waiting for the silence that would tell it a second later."""
        for sysid in list(self._connected):
            self._lose(sysid, reason)

    def _lose(self, sysid: int, why: str) -> None:
        self._connected.discard(sysid)
        log.warning("link %s: vehicle %d lost (%s)", self._link_name, sysid, why)
        self._vehicles[sysid].set_connected(
            False, why, silent_since_s=self.liveness.last_frame_s(sysid))

    async def close(self) -> None:
        for vehicle in list(self._vehicles.values()):
            await _close_vehicle(vehicle)


def _put_drop_oldest(queue: asyncio.Queue[Any], item: Any) -> None:
    if queue.full():
        queue.get_nowait()
    queue.put_nowait(item)


async def _close_vehicle(vehicle: Vehicle) -> None:
    """Stop a vehicle's own tasks (its streamer) if it has a close()."""
    close = getattr(vehicle, "close", None)
    if close is None:
        return
    result = close()
    if asyncio.iscoroutine(result):
        await result
