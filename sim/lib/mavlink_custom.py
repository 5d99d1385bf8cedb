"""MAVLink messages PX4 v1.16 sends that pymavlink's generated dialect lacks.

PX4 builds with a newer common.xml than pymavlink ships: PROTOCOL_VERSION (300),
LINK_NODE_STATUS (8), TIME_ESTIMATE_TO_TARGET (380) and CURRENT_EVENT_SEQUENCE (411) are
packed here from their wire layout (fields ordered by size, as MAVLink 2 sends them) and the
CRC extra of PX4's generated headers. A receiver with the older dialect sees them as
UNKNOWN_<id>, as it would from PX4.
"""

from __future__ import annotations

import struct
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

MAVLINK_MSG_ID_LINK_NODE_STATUS = 8
MAVLINK_MSG_ID_PROTOCOL_VERSION = 300
MAVLINK_MSG_ID_TIME_ESTIMATE_TO_TARGET = 380
MAVLINK_MSG_ID_CURRENT_EVENT_SEQUENCE = 411


class CustomMessage(mavlink.MAVLink_message):  # type: ignore[misc]
    """A message packed from its wire layout; subclasses give id, name, CRC and fields."""

    id = 0
    msgname = ""
    crc_extra = 0
    fieldnames: tuple[str, ...] = ()
    _wire = struct.Struct("<")

    def __init__(self, *values: Any) -> None:
        super().__init__(self.id, self.msgname)
        self._fieldnames = list(self.fieldnames)
        self._values = values
        for name, value in zip(self.fieldnames, values, strict=True):
            setattr(self, name, value)

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        payload = self._wire.pack(*self._values)
        packed: bytes = self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1)
        return packed


def _message_type(name: str, msg_id: int, crc_extra: int, wire_format: str,
                  fieldnames: str) -> type[CustomMessage]:
    """A CustomMessage subclass for one message of common.xml (fields in wire order)."""
    attributes = {"id": msg_id, "msgname": name, "crc_extra": crc_extra,
                  "fieldnames": tuple(fieldnames.split()), "_wire": struct.Struct(wire_format)}
    return type(f"{name.title().replace('_', '')}Message", (CustomMessage,), attributes)


# the MAVLink versions spoken (100 × major) and the spec's and library's git hashes
ProtocolVersionMessage = _message_type(
    "PROTOCOL_VERSION", MAVLINK_MSG_ID_PROTOCOL_VERSION, 217, "<HHH8s8s",
    "version min_version max_version spec_version_hash library_version_hash")
# the link's own traffic counters
LinkNodeStatusMessage = _message_type(
    "LINK_NODE_STATUS", MAVLINK_MSG_ID_LINK_NODE_STATUS, 117, "<QIIIIIHHHBB",
    "timestamp tx_rate rx_rate messages_sent messages_received messages_lost rx_parse_err "
    "tx_overflows rx_overflows tx_buf rx_buf")
# seconds to return, to land, to the mission item and end, to the command's end (-1 = none)
TimeEstimateToTargetMessage = _message_type(
    "TIME_ESTIMATE_TO_TARGET", MAVLINK_MSG_ID_TIME_ESTIMATE_TO_TARGET, 232, "<iiiii",
    "safe_return land mission_next_item mission_end commanded_action")
# the newest event's sequence number
CurrentEventSequenceMessage = _message_type(
    "CURRENT_EVENT_SEQUENCE", MAVLINK_MSG_ID_CURRENT_EVENT_SEQUENCE, 106, "<HB",
    "sequence flags")
