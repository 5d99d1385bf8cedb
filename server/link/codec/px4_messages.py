"""MAVLink messages of the events and component-metadata protocols that pymavlink's
generated dialect lacks, so the link can read them as PX4 v1.16 sends them.

PX4 builds with a newer common.xml than pymavlink ships, so the messages the vehicle sends
(COMPONENT_INFORMATION 395, COMPONENT_METADATA 397, EVENT 410, CURRENT_EVENT_SEQUENCE 411,
RESPONSE_EVENT_ERROR 413) reach pymavlink's parser as UNKNOWN_<id>, whose checksum it cannot
check. decode_unknown() reads them from their wire layout (fields ordered by size) once the
checksum holds with the CRC extra of PX4's generated headers. pymavlink's own decoder map is
left as it is: it is shared by everything in the process that parses MAVLink.
REQUEST_EVENT (412), which only the ground sends, is packed here.
"""

from __future__ import annotations

import struct
from typing import Any, ClassVar

from pymavlink.dialects.v20 import development as mavlink

MAVLINK_MSG_ID_LINK_NODE_STATUS = 8
MAVLINK_MSG_ID_PROTOCOL_VERSION = 300
MAVLINK_MSG_ID_TIME_ESTIMATE_TO_TARGET = 380
MAVLINK_MSG_ID_COMPONENT_INFORMATION = 395
MAVLINK_MSG_ID_COMPONENT_METADATA = 397
MAVLINK_MSG_ID_EVENT = 410
MAVLINK_MSG_ID_CURRENT_EVENT_SEQUENCE = 411
MAVLINK_MSG_ID_REQUEST_EVENT = 412
MAVLINK_MSG_ID_RESPONSE_EVENT_ERROR = 413
MAV_EVENT_CURRENT_SEQUENCE_FLAGS_RESET = 1
EVENT_ARGUMENTS_LEN = 40


class _WireMessage(mavlink.MAVLink_message):  # type: ignore[misc]
    """A message decoded and packed from its wire layout (fields listed in wire order)."""

    # set by _message_type for each message
    id: ClassVar[int]
    msgname: ClassVar[str]
    crc_extra: ClassVar[int]
    fieldnames: ClassVar[list[str]]
    unpacker: ClassVar[struct.Struct]

    def __init__(self, *values: Any) -> None:
        super().__init__(self.id, self.msgname)
        self._fieldnames = list(self.fieldnames)
        self._instance_field = None
        self._instance_offset = -1
        for name, value in zip(self.fieldnames, values, strict=True):
            setattr(self, name, value)

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        payload = self.unpacker.pack(*(getattr(self, name) for name in self.fieldnames))
        packed: bytes = self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1)
        return packed


def _message_type(
    name: str, msg_id: int, crc_extra: int, wire_format: str, fieldnames: str
) -> type[_WireMessage]:
    names = fieldnames.split()
    unpacker = struct.Struct(wire_format)
    attributes: dict[str, object] = {
        "id": msg_id, "msgname": name, "crc_extra": crc_extra, "fieldnames": names,
        "ordered_fieldnames": names, "unpacker": unpacker,
        "native_format": bytearray(wire_format.encode()),
        # one struct item per field (strings and the argument bytes as "Ns"), so pymavlink's
        # decoder takes them in wire order as they are
        "orders": list(range(len(names))), "lengths": [1] * len(names),
        "array_lengths": [0] * len(names), "fieldtypes": ["uint8_t"] * len(names),
        "instance_field": None, "instance_offset": -1, "fielddisplays_by_name": {},
        "fieldenums_by_name": {}, "fieldunits_by_name": {},
    }  # fmt: skip
    return type(f"MAVLink_{name.lower()}_message", (_WireMessage,), attributes)


ComponentInformationMessage = _message_type(
    "COMPONENT_INFORMATION",
    MAVLINK_MSG_ID_COMPONENT_INFORMATION,
    0,
    "<III100s100s",
    "time_boot_ms general_metadata_file_crc peripherals_metadata_file_crc "
    "general_metadata_uri peripherals_metadata_uri",
)
ComponentMetadataMessage = _message_type(
    "COMPONENT_METADATA",
    MAVLINK_MSG_ID_COMPONENT_METADATA,
    182,
    "<II100s",
    "time_boot_ms file_crc uri",
)
EventMessage = _message_type(
    "EVENT",
    MAVLINK_MSG_ID_EVENT,
    160,
    "<IIHBBB40s",
    "id event_time_boot_ms sequence destination_component destination_system log_levels arguments",
)
CurrentEventSequenceMessage = _message_type(
    "CURRENT_EVENT_SEQUENCE", MAVLINK_MSG_ID_CURRENT_EVENT_SEQUENCE, 106, "<HB", "sequence flags"
)
RequestEventMessage = _message_type(
    "REQUEST_EVENT",
    MAVLINK_MSG_ID_REQUEST_EVENT,
    33,
    "<HHBB",
    "first_sequence last_sequence target_system target_component",
)
ResponseEventErrorMessage = _message_type(
    "RESPONSE_EVENT_ERROR",
    MAVLINK_MSG_ID_RESPONSE_EVENT_ERROR,
    77,
    "<HHBBB",
    "sequence sequence_oldest_available target_system target_component reason",
)

# Streamed by PX4 v1.16 on its links (mavlink_main.cpp), read only so that their checksum
# is checked: a frame nobody can check is dropped by the link.
LinkNodeStatusMessage = _message_type(
    "LINK_NODE_STATUS", MAVLINK_MSG_ID_LINK_NODE_STATUS, 117, "<QIIIIIHHHBB",
    "timestamp tx_rate rx_rate messages_sent messages_received messages_lost rx_parse_err "
    "tx_overflows rx_overflows tx_buf rx_buf",
)
TimeEstimateToTargetMessage = _message_type(
    "TIME_ESTIMATE_TO_TARGET", MAVLINK_MSG_ID_TIME_ESTIMATE_TO_TARGET, 232, "<iiiii",
    "safe_return land mission_next_item mission_end commanded_action",
)
ProtocolVersionMessage = _message_type(
    "PROTOCOL_VERSION", MAVLINK_MSG_ID_PROTOCOL_VERSION, 217, "<HHH8s8s",
    "version min_version max_version spec_version_hash library_version_hash",
)

_RECEIVED: dict[int, type[_WireMessage]] = {
    cls.id: cls
    for cls in (
        ComponentInformationMessage,
        ComponentMetadataMessage,
        EventMessage,
        CurrentEventSequenceMessage,
        ResponseEventErrorMessage,
        LinkNodeStatusMessage,
        TimeEstimateToTargetMessage,
        ProtocolVersionMessage,
    )
}
_MAVLINK2_STX = 0xFD
_MAVLINK2_HEADER_LEN = 10


def decode_unknown(msg: mavlink.MAVLink_message) -> mavlink.MAVLink_message | None:
    """The message an UNKNOWN_<id> frame holds, when it is one of the messages above and its
    checksum holds with that message's CRC extra; None for anything else (a frame nobody
    can vouch for)."""
    frame = bytes(msg.get_msgbuf())
    if len(frame) < _MAVLINK2_HEADER_LEN + 2 or frame[0] != _MAVLINK2_STX:
        return None
    length = frame[1]
    msg_id = frame[7] | frame[8] << 8 | frame[9] << 16
    cls = _RECEIVED.get(msg_id)
    end = _MAVLINK2_HEADER_LEN + length
    if cls is None or len(frame) < end + 2:
        return None
    crc = mavlink.x25crc(frame[1:end])
    crc.accumulate(bytes([cls.crc_extra]))
    if crc.crc != frame[end] | frame[end + 1] << 8:
        return None
    # MAVLink 2 trims trailing zero bytes off the payload
    payload = frame[_MAVLINK2_HEADER_LEN:end].ljust(cls.unpacker.size, b"\0")
    decoded = cls(*cls.unpacker.unpack(payload[: cls.unpacker.size]))
    decoded._header = mavlink.MAVLink_header(
        msg_id, frame[2], frame[3], length, frame[4], frame[5], frame[6]
    )
    decoded._msgbuf = bytearray(frame)
    decoded._payload = payload
    return decoded


def event_arguments(msg: Any) -> bytes:
    """An EVENT's 40 argument bytes (MAVLink 2 trims trailing zeros off the wire)."""
    return bytes(msg.arguments).ljust(EVENT_ARGUMENTS_LEN, b"\0")


def text_field(value: bytes | str) -> str:
    """A char[] field as text, without its NUL padding."""
    raw = value.encode() if isinstance(value, str) else value
    return raw.rstrip(b"\0").decode("utf-8", "replace")
