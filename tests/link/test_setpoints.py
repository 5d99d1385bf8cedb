"""Setpoint -> MAVLink golden tests: messages, frames and type masks (MAVSDK's values)."""

from __future__ import annotations

import math
import struct

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec import setpoints as sp
from server.link.codec.setpoints import encode, resolve
from skyhelm_wire.setpoint_kinds import kind_fields

MAV = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)


def _encoded(setpoint: sp.Setpoint) -> tuple[mavlink.MAVLink_message, sp.SentSetpoint]:
    msg, sent = encode(setpoint, MAV, 1, 1)
    decoded = MAV.decode(bytearray(msg.pack(MAV)))  # what the vehicle really reads
    return decoded, sent


@pytest.mark.parametrize(
    ("setpoint", "message", "frame", "type_mask"),
    [
        (sp.PositionNed(1, 2, -3, yaw_deg=90), "SET_POSITION_TARGET_LOCAL_NED", 1, 2552),
        (sp.VelocityNed(1, 0, 0, yaw_deg=0), "SET_POSITION_TARGET_LOCAL_NED", 1, 2503),
        (sp.VelocityNed(1, 0, 0, yaw_rate_deg_s=10), "SET_POSITION_TARGET_LOCAL_NED", 1, 1479),
        (sp.VelocityBody(1, 0, 0, yaw_rate_deg_s=5), "SET_POSITION_TARGET_LOCAL_NED", 8, 1479),
        (sp.AccelerationNed(0, 1, 0), "SET_POSITION_TARGET_LOCAL_NED", 1, 3135),
        (sp.PositionVelocityNed(1, 2, -3, 1, 0, 0, yaw_deg=0),
         "SET_POSITION_TARGET_LOCAL_NED", 1, 2496),
        (sp.PositionVelocityNed(1, 2, -3, 1, 0, 0, 0.1, 0.2, 0.3, yaw_deg=0),
         "SET_POSITION_TARGET_LOCAL_NED", 1, 2048),
        (sp.PositionGlobal(47.1, 8.5, 500, yaw_deg=0), "SET_POSITION_TARGET_GLOBAL_INT", 5, 2552),
        (sp.PositionGlobal(47.1, 8.5, 10, "relative", yaw_deg=0),
         "SET_POSITION_TARGET_GLOBAL_INT", 6, 2552),
        (sp.PositionGlobal(47.1, 8.5, 10, "terrain", yaw_deg=0),
         "SET_POSITION_TARGET_GLOBAL_INT", 11, 2552),
        (sp.Attitude(5, -5, 90, 0.5), "SET_ATTITUDE_TARGET", 0, 7),
        (sp.BodyRates(10, 0, 0, 0.5), "SET_ATTITUDE_TARGET", 0, 128),
    ],
)  # fmt: skip
def test_setpoint_encodes_to_the_message_frame_and_type_mask_px4_expects(
    setpoint: sp.Setpoint, message: str, frame: int, type_mask: int
) -> None:
    decoded, sent = _encoded(setpoint)

    assert (sent.message, sent.frame, sent.type_mask) == (message, frame, type_mask)
    assert decoded.get_type() == message
    assert decoded.type_mask == type_mask
    if message != "SET_ATTITUDE_TARGET":
        assert decoded.coordinate_frame == frame
    assert (decoded.target_system, decoded.target_component) == (1, 1)


def test_position_fields_and_yaw_in_radians_go_on_the_wire() -> None:
    decoded, _ = _encoded(sp.PositionNed(1.5, -2.0, -3.0, yaw_deg=90))

    assert (decoded.x, decoded.y, decoded.z) == (1.5, -2.0, -3.0)
    assert decoded.yaw == pytest.approx(math.pi / 2)


def test_global_position_is_sent_in_deg_e7() -> None:
    decoded, _ = _encoded(sp.PositionGlobal(47.3977421, 8.5455941, 12.5, "relative", 0))

    assert (decoded.lat_int, decoded.lon_int) == (473977421, 85455941)
    assert decoded.alt == pytest.approx(12.5)


def test_attitude_becomes_a_unit_quaternion_of_the_euler_angles() -> None:
    decoded, _ = _encoded(sp.Attitude(0, 0, 90, 0.6))

    w, x, y, z = decoded.q
    assert (w, x, y, z) == pytest.approx((math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)))
    assert decoded.thrust == pytest.approx(0.6)


def test_missing_yaw_sets_the_yaw_ignore_bit() -> None:
    _, sent = _encoded(sp.PositionNed(0, 0, -5))

    assert sent.type_mask == 2552 | sp.POSITION_TARGET_TYPEMASK_YAW_IGNORE


def test_raw_local_goes_out_unchanged() -> None:
    decoded, sent = _encoded(sp.RawLocal(frame=1, type_mask=0b110111111000, x=1, y=2, z=-3))

    assert (sent.frame, sent.type_mask) == (1, 3576)
    assert (decoded.x, decoded.y, decoded.z) == (1, 2, -3)


def test_offset_ned_resolves_to_local_ned_from_the_current_position() -> None:
    resolved = resolve(sp.OffsetNed(2, -1, -0.5), (10.0, 20.0, -5.0), 45.0)

    assert resolved == sp.PositionNed(12.0, 19.0, -5.5, 45.0)


def test_offset_body_rotates_by_the_current_yaw() -> None:
    resolved = resolve(sp.OffsetBody(forward_m=2, right_m=1, down_m=0), (1.0, 1.0, -3.0), 90.0)

    assert isinstance(resolved, sp.PositionNed)
    assert (resolved.north_m, resolved.east_m, resolved.down_m) == pytest.approx((0, 3, -3))
    assert resolved.yaw_deg == 90.0


def test_offset_without_a_position_cannot_be_resolved() -> None:
    with pytest.raises(LookupError):
        resolve(sp.OffsetNed(1, 0, 0), None, None)


def test_missing_yaw_is_pinned_to_the_current_heading_but_yaw_rate_is_kept() -> None:
    assert resolve(sp.PositionNed(1, 2, 3), (0, 0, 0), 30.0) == sp.PositionNed(1, 2, 3, 30.0)
    with_rate = sp.VelocityNed(1, 0, 0, yaw_rate_deg_s=5)
    assert resolve(with_rate, (0, 0, 0), 30.0) == with_rate


def test_describe_names_the_kind_and_its_fields() -> None:
    assert sp.describe(sp.VelocityBody(1, 0, 0)) == {
        "type": "velocity_body", "forward_m_s": 1, "right_m_s": 0, "down_m_s": 0,
        "yaw_rate_deg_s": None,
    }  # fmt: skip


def test_every_kind_has_one_snake_case_name_and_units_on_its_numbers() -> None:
    assert list(sp.SETPOINT_KINDS) == [kind.kind for kind in sp.SETPOINT_KINDS.values()]
    for name, kind in sp.SETPOINT_KINDS.items():
        assert name == name.lower()
        assert " " not in name
        for field in kind_fields(kind):
            if field.quantity is not None:
                assert field.quantity.ge < field.quantity.le, (name, field.name)


def test_every_limit_is_packable_into_the_float32_the_wire_carries() -> None:
    for kind in sp.SETPOINT_KINDS.values():
        for field in kind_fields(kind):
            if field.quantity is not None:
                for bound in (field.quantity.ge, field.quantity.le):
                    struct.pack("<f", bound)
                    assert abs(bound) < 3.4e38
