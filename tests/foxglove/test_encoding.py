"""What the channels carry, without a vehicle: schemas in the subset Foxglove reads, every
MAVLink message as JSON its schema describes, NED/FRD attitudes as ENU/FLU rotations."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from foxglove.messages import LogLevel
from pymavlink.dialects.v20 import development as mavlink

from server.foxglove.bridge import event_log
from server.foxglove.derived import enu_flu_quaternion
from server.foxglove.layout import layout_json
from server.foxglove.mavlink_json import message_json
from server.foxglove.schemas import HEALTH_SCHEMA, STATE_SCHEMA, foxglove_schema, mavlink_schema
from server.link import VehicleEvent
from server.link.codec import px4_messages
from tests.foxglove.ws_client import check_conforms, check_foxglove_json_schema

_MAV = mavlink.MAVLink(None, 1, 1)
LAYOUT_FILE = Path(__file__).resolve().parents[2] / "docs" / "foxglove-layout.json"


def test_the_state_and_health_schemas_are_in_foxgloves_subset() -> None:
    check_foxglove_json_schema(STATE_SCHEMA, "state")
    check_foxglove_json_schema(HEALTH_SCHEMA, "health")
    properties = STATE_SCHEMA["properties"]
    assert properties["global"]["properties"]["lat_deg"] == {"type": "number"}
    # the setpoint kinds' union is one object with every kind's fields
    assert {"type", "north_m", "north_m_s"} <= properties["setpoint"]["properties"].keys()


def test_nullable_and_referenced_fields_become_their_plain_type() -> None:
    schema = foxglove_schema({
        "type": "object",
        "properties": {
            "a": {"anyOf": [{"type": "number"}, {"type": "null"}], "description": "metres"},
            "b": {"$ref": "#/$defs/B"},
            "c": {"type": "object", "additionalProperties": {"type": "number"}},
        },
        "$defs": {"B": {"type": "array", "items": {"enum": ["x", "y"]}}},
    })
    assert schema["properties"] == {
        "a": {"type": "number", "description": "metres"},
        "b": {"type": "array", "items": {"type": "string"}},
        "c": {"type": "object", "properties": {}},
    }


def _decoded(msg: mavlink.MAVLink_message) -> mavlink.MAVLink_message:
    """The message as a receiver decodes it from its frame."""
    frame = msg.pack(_MAV)
    decoded = mavlink.MAVLink(None).decode(bytearray(frame))
    if isinstance(decoded, mavlink.MAVLink_unknown):
        decoded = px4_messages.decode_unknown(decoded)
    assert decoded is not None
    return decoded


@pytest.mark.parametrize(
    "msg",
    [
        mavlink.MAVLink_attitude_quaternion_message(
            1, 1, 0, 0, 0, 0.1, 0.2, math.nan, [0, 0, 0, 0]),
        mavlink.MAVLink_statustext_message(4, b"Takeoff NaN detected", 0, 0),
        mavlink.MAVLink_set_position_target_local_ned_message(
            5, 1, 1, 1, 3576, 1.0, 2.0, -3.0, *[math.nan] * 8),
        mavlink.MAVLink_gps_raw_int_message(1, 3, 1, 2, 3, 4, 5, 6, 7, 8),
        px4_messages.EventMessage(7, 100, 3, 1, 1, 6, bytes([4, 0, 255] + [0] * 37)),
        mavlink.MAVLink_file_transfer_protocol_message(0, 1, 1, list(range(251))),
    ],
    ids=lambda msg: msg.get_type(),
)
def test_a_mavlink_message_is_json_its_schema_describes(msg: mavlink.MAVLink_message) -> None:
    decoded = _decoded(msg)
    schema = mavlink_schema(decoded)
    check_foxglove_json_schema(schema, decoded.get_type())
    value = json.loads(message_json(decoded))  # strict JSON: no NaN
    check_conforms(value, schema, decoded.get_type())
    assert value["_compid"] == 1
    assert set(value) == set(schema["properties"])


def test_nan_is_null_and_numbers_stay() -> None:
    value = json.loads(message_json(_decoded(
        mavlink.MAVLink_set_position_target_local_ned_message(
            5, 1, 1, 1, 3576, 1.0, 2.0, -3.0, *[math.nan] * 8)
    )))
    assert (value["x"], value["y"], value["z"], value["vx"]) == (1.0, 2.0, -3.0, None)


def _matrix(q: tuple[float, float, float, float]) -> np.ndarray:
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _ned_frd(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch),
                              math.sin(pitch), math.cos(yaw), math.sin(yaw))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


@pytest.mark.parametrize("angles_deg", [(0, 0, 0), (0, 0, 90), (10, -20, 135), (-45, 30, -170)])
def test_the_attitude_is_the_same_rotation_in_enu_and_flu(
    angles_deg: tuple[float, float, float],
) -> None:
    roll, pitch, yaw = (math.radians(a) for a in angles_deg)
    q = enu_flu_quaternion(roll, pitch, yaw)
    enu_from_ned = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]])
    frd_from_flu = np.diag([1, -1, -1])
    expected = enu_from_ned @ _ned_frd(roll, pitch, yaw) @ frd_from_flu
    np.testing.assert_allclose(_matrix(q), expected, atol=1e-9)


def test_events_are_log_lines_with_their_own_text_or_their_data() -> None:
    lost = VehicleEvent("connection", 0.0, {"connected": False, "text": "link lost: silence"})
    assert event_log(lost) == (LogLevel.Warning, "link lost: silence")
    armed = VehicleEvent("armed", 0.0, {"armed": True})
    assert event_log(armed) == (LogLevel.Info, 'armed: {"armed": true}')
    px4 = VehicleEvent("px4_event", 0.0, {"severity": "error", "text": "Preflight Fail"})
    assert event_log(px4) == (LogLevel.Error, "Preflight Fail")


def test_the_layout_in_the_docs_is_the_one_the_code_builds() -> None:
    assert LAYOUT_FILE.read_text() == layout_json(), (
        "docs/foxglove-layout.json is stale: python -m server.foxglove.layout > it"
    )
    text = LAYOUT_FILE.read_text()
    for topic in ("/vehicle_1/location", "/vehicle_1/pose", "/vehicle_1/log",
                  "/vehicle_1/state.attitude.roll_deg", "/vehicle_1/state.global.alt_rel_m"):
        assert f'"{topic}' in text
