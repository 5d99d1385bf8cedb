"""Outgoing frames packed by sim.mavlink.frames are byte for byte what pymavlink packs."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import development as mavlink

from sim.lib import modes
from sim.mavlink.endpoint import MavlinkCodec
from sim.mavlink.frames import pack_frame
from sim.mavlink.streams import FIXED_WING_ONLY
from sim.vehicle import SimVehicle


def pymavlink_frame(msg: Any, seq: int, sysid: int = 1, compid: int = 1) -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.seq = seq
    packed: bytes = msg.pack(mav)
    return packed


def flying_vehicle() -> SimVehicle:
    v = SimVehicle("quad")
    for _ in range(1000):
        v.step()
    v.commander.request_mode(modes.AUTO_TAKEOFF)
    v.commander.arm(v.now_s)
    for _ in range(500):
        v.step()
    return v


def test_every_telemetry_message_packs_like_pymavlink() -> None:
    v = flying_vehicle()
    # a quad sends no fixed-wing controller status
    wanted = [msg_id for msg_id in v.messages.builders if msg_id not in FIXED_WING_ONLY]
    messages = [m for m in map(v.messages.build, wanted) if m is not None]
    assert len(messages) == len(wanted)
    for seq, msg in enumerate(messages):
        frame = pack_frame(msg, seq, 7, 1)
        if frame is None:  # a message type pymavlink's dialect lacks: pymavlink packs it
            continue
        assert frame == pymavlink_frame(msg, seq, 7, 1), msg.get_type()


@pytest.mark.parametrize("msg", [
    mavlink.MAVLink_statustext_message(6, b"RTL: land at destination", 3, 1),
    mavlink.MAVLink_command_ack_message(mavlink.MAV_CMD_DO_SET_MODE, 0, 0, 0, 255, 190),
    mavlink.MAVLink_param_value_message(b"MIS_TAKEOFF_ALT", 2.5, 9, 412, 17),
    mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3),  # all-zero tail: one byte kept
])
def test_acks_texts_and_params_pack_like_pymavlink(msg: Any) -> None:
    assert pack_frame(msg, 255, 1, 1) == pymavlink_frame(msg, 255)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.integers(0, 65535), min_size=10, max_size=10),
    st.integers(-32768, 32767),
    st.integers(-1, 100),
    st.floats(allow_nan=True, width=32),
)
def test_array_and_float_fields_pack_like_pymavlink(
    voltages: list[int], current_cca: int, remaining: int, roll: float
) -> None:
    battery = mavlink.MAVLink_battery_status_message(
        0, 0, 1, 32767, voltages, current_cca, 1200, -1, remaining)
    attitude = mavlink.MAVLink_attitude_message(1234, roll, 0.0, -roll, 0.0, 0.0, 0.0)
    for msg in (battery, attitude):
        assert pack_frame(msg, 9, 1, 1) == pymavlink_frame(msg, 9)


def test_codec_numbers_frames_and_wraps_the_sequence() -> None:
    codec = MavlinkCodec(3, 1)
    msg = mavlink.MAVLink_command_ack_message(400, 0)
    seqs = [codec.encode(msg)[4] for _ in range(258)]
    assert seqs[:3] == [0, 1, 2]
    assert seqs[255:] == [255, 0, 1]
    parsed = mavlink.MAVLink(None).parse_buffer(codec.encode(msg))
    assert parsed is not None
    assert parsed[0].get_srcSystem() == 3


def test_fields_beyond_their_wire_type_are_saturated_not_raised() -> None:
    msg = mavlink.MAVLink_global_position_int_message(
        1, 2**40, float("nan"), -1e300, 5, 10**12, -(2**20), 3, 99999)
    frame = pack_frame(msg, 0, 1, 1)
    assert frame is not None
    (decoded,) = mavlink.MAVLink(None).parse_buffer(frame) or []
    assert decoded.lat == 2**31 - 1
    assert decoded.lon == 0
    assert decoded.alt == -(2**31)
    assert decoded.relative_alt == 5
    assert (decoded.vx, decoded.vy, decoded.vz) == (2**15 - 1, -(2**15), 3)
    assert decoded.hdg == 65535
    huge = mavlink.MAVLink_local_position_ned_message(1, 1e300, -1e300, float("inf"), 0, 0, 0)
    (decoded,) = mavlink.MAVLink(None).parse_buffer(pack_frame(huge, 0, 1, 1) or b"") or []
    assert decoded.x == pytest.approx(3.4028234663852886e38)
    assert decoded.y == pytest.approx(-3.4028234663852886e38)
    assert decoded.z == float("inf")


def test_in_range_frames_are_not_altered_by_the_fitting() -> None:
    msg = mavlink.MAVLink_global_position_int_message(
        1, 2**31 - 1, -(2**31), 0, -5, 1, -(2**15), 2**15 - 1, 65535)
    assert pack_frame(msg, 3, 1, 1) == pymavlink_frame(msg, 3)
