"""What the MAVLink module answers about events: REQUEST_EVENT, component metadata requests
and MAVLink FTP reads of the metadata files; it also puts the commander's events on the links."""

from __future__ import annotations

from sim.lib.events import request_event_fields
from sim.mavlink import component_metadata
from sim.mavlink.mavlink_ftp import FtpServer
from sim.mavlink.vehicle_interface import Link, Message, VehicleInterface


class EventServices:
    def __init__(self, vehicle: VehicleInterface) -> None:
        self._v = vehicle
        self._metadata = component_metadata.shared()
        self._ftp = FtpServer(self._metadata.files, vehicle.sysid, vehicle.compid)
        # SimVehicle says when it has booted; nothing goes out before (as from PX4)
        vehicle.commander.events.attach(
            vehicle.broadcast, lambda: bool(getattr(vehicle, "booted", True)))

    def handle_ftp(self, link: Link, msg: Message) -> None:
        self._ftp.handle(link, msg)

    def handle_unknown(self, link: Link, msg: Message) -> None:
        """Messages pymavlink's dialect lacks; REQUEST_EVENT is the one the vehicle takes."""
        request = request_event_fields(msg)
        if request is None or request.target_system != self._v.sysid:
            return
        if request.target_component not in (self._v.compid, 0):
            return
        self._v.commander.events.handle_request(
            request.first_sequence, request.last_sequence, request.source_system,
            request.source_component, link.send)

    def build(self, msg_id: int) -> Message | None:
        """COMPONENT_METADATA / COMPONENT_INFORMATION, None for other messages."""
        return self._metadata.build(msg_id, round(self._v.now_s * 1000))
