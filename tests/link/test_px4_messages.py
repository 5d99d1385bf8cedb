"""Messages pymavlink's dialect lacks are read by the link only when their checksum holds,
and pymavlink's shared decoder map is left alone (a simulated vehicle in the same process
parses with it too)."""

from __future__ import annotations

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec import px4_messages
from server.link.codec.px4_messages import EventMessage, decode_unknown


def _frame() -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=3, srcComponent=1)
    mav.seq = 42
    event = EventMessage(0x01020304, 1234, 77, 0, 0, 0x62, bytes(range(1, 9)).ljust(40, b"\0"))
    return bytes(event.pack(mav))


def _parsed(frame: bytes) -> mavlink.MAVLink_message:
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    (msg,) = parser.parse_buffer(frame)
    return msg


def test_an_event_frame_is_decoded_with_its_header() -> None:
    unknown = _parsed(_frame())
    assert isinstance(unknown, mavlink.MAVLink_unknown)

    event = decode_unknown(unknown)

    assert event is not None
    assert event.get_type() == "EVENT"
    assert (event.id, event.event_time_boot_ms, event.sequence, event.log_levels) == (
        0x01020304, 1234, 77, 0x62)  # fmt: skip
    assert px4_messages.event_arguments(event)[:8] == bytes(range(1, 9))
    assert (event.get_srcSystem(), event.get_srcComponent(), event.get_seq()) == (3, 1, 42)


def test_a_frame_whose_checksum_fails_is_not_decoded() -> None:
    frame = bytearray(_frame())
    frame[12] ^= 0xFF  # a payload byte: pymavlink cannot tell for an id it does not know
    unknown = _parsed(bytes(frame))
    assert isinstance(unknown, mavlink.MAVLink_unknown)

    assert decode_unknown(unknown) is None


def test_pymavlinks_shared_decoder_map_is_left_alone() -> None:
    assert px4_messages.MAVLINK_MSG_ID_EVENT not in mavlink.mavlink_map
