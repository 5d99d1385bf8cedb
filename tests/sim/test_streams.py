"""Telemetry out: per-link stream rates, message contents, SET_MESSAGE_INTERVAL, battery."""

from __future__ import annotations

import math
from collections import Counter

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.lib import modes
from sim.lib.events import CURRENT_SEQUENCE_INTERVAL_S, MAVLINK_MSG_ID_EVENT
from sim.lib.mavlink_custom import (
    MAVLINK_MSG_ID_CURRENT_EVENT_SEQUENCE as CURRENT_EVENT_SEQUENCE_ID,
)
from sim.mavlink.streams import (
    FAST_FORWARD_CAP_HZ,
    FIXED_WING_ONLY,
    NORMAL_RATES_HZ,
    ONBOARD_RATES_HZ,
)
from tests.sim.conftest import Harness, HarnessFactory

WINDOW_S = 10.0


def rates_hz(messages: list[object], seconds: float) -> dict[str, float]:
    counts = Counter(m.get_type() for m in messages)  # type: ignore[attr-defined]
    return {name: n / seconds for name, n in counts.items()}


def type_name(msg_id: int) -> str:
    """pymavlink's name for msg_id; messages outside its dialect decode as UNKNOWN_<id>."""
    cls = mavlink.mavlink_map.get(msg_id)
    return cls.msgname if cls is not None else f"UNKNOWN_{msg_id}"


@pytest.mark.parametrize(("link_name", "table"), [("api", ONBOARD_RATES_HZ),
                                                  ("gcs", NORMAL_RATES_HZ)])
def test_each_link_streams_at_px4_default_rates(harness: Harness, link_name: str,
                                                table: dict[int, float]) -> None:
    link = getattr(harness, link_name)
    link.clear()
    harness.run(WINDOW_S)
    measured = rates_hz(link.sent, WINDOW_S)
    table = {msg_id: hz for msg_id, hz in table.items() if msg_id not in FIXED_WING_ONLY}
    for msg_id, hz in table.items():
        name = type_name(msg_id)
        assert measured.get(name, 0.0) == pytest.approx(hz, rel=0.1, abs=0.11), name
    # CURRENT_EVENT_SEQUENCE belongs to the events protocol, every 3 s on each link as PX4
    events_protocol = {type_name(CURRENT_EVENT_SEQUENCE_ID): 1 / CURRENT_SEQUENCE_INTERVAL_S}
    for name, hz in events_protocol.items():
        assert measured.get(name, 0.0) == pytest.approx(hz, abs=0.11), name
    # EVENT goes out as things happen (here the arming check report made at ready)
    as_they_happen = {type_name(MAVLINK_MSG_ID_EVENT)}
    unexpected = set(measured) - {type_name(i) for i in table} - set(events_protocol)
    unexpected -= as_they_happen
    assert unexpected == set()


def test_set_message_interval_changes_only_that_link(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                         mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 20_000)  # 50 Hz
    harness.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                         mavlink.MAVLINK_MSG_ID_ATTITUDE, -1)
    harness.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                         mavlink.MAVLINK_MSG_ID_BATTERY_STATUS, 500_000)  # new stream, 2 Hz
    assert [a.result for a in harness.api.acks()] == [mavlink.MAV_RESULT_ACCEPTED] * 3
    harness.api.clear()
    harness.gcs.clear()
    harness.run(4.0)
    api = rates_hz(harness.api.sent, 4.0)
    assert api["LOCAL_POSITION_NED"] == pytest.approx(50.0, rel=0.05)
    assert "ATTITUDE" not in api
    assert api["BATTERY_STATUS"] == pytest.approx(2.0, rel=0.15)
    gcs_attitude_hz = NORMAL_RATES_HZ[mavlink.MAVLINK_MSG_ID_ATTITUDE]
    assert rates_hz(harness.gcs.sent, 4.0)["ATTITUDE"] == pytest.approx(gcs_attitude_hz, rel=0.1)


def test_interval_zero_restores_the_default_rate(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                         mavlink.MAVLINK_MSG_ID_ATTITUDE, -1)
    harness.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                         mavlink.MAVLINK_MSG_ID_ATTITUDE, 0)
    harness.api.clear()
    harness.run(2.0)
    assert rates_hz(harness.api.sent, 2.0)["ATTITUDE"] == pytest.approx(100.0, rel=0.05)


@pytest.mark.parametrize("speed", [8.0, 2.0])
def test_a_fast_forward_caps_each_stream_per_wall_second(harness: Harness, speed: float) -> None:
    """Faster than real time a stream keeps its sim-time rate up to FAST_FORWARD_CAP_HZ of
    wall time (its own rate when faster); back at real time every rate is PX4's again."""
    harness.vehicle.wall_speed = lambda: speed
    harness.api.clear()
    harness.run(WINDOW_S)
    measured_sim_hz = rates_hz(harness.api.sent, WINDOW_S)
    capped = 0
    for msg_id, hz in ONBOARD_RATES_HZ.items():
        if msg_id in FIXED_WING_ONLY:
            continue
        wall_cap_hz = max(hz, FAST_FORWARD_CAP_HZ)
        expected_sim_hz = min(hz, wall_cap_hz / speed)
        capped += expected_sim_hz < hz
        name = type_name(msg_id)
        assert measured_sim_hz.get(name, 0.0) == pytest.approx(
            expected_sim_hz, rel=0.1, abs=0.11), name
    assert capped >= (12 if speed == 8.0 else 1)  # the premise: the cap acts at this speed
    harness.vehicle.wall_speed = lambda: 1.0
    harness.run(1.0)  # each stream's next deadline is at its own interval again
    harness.api.clear()
    harness.run(2.0)
    assert rates_hz(harness.api.sent, 2.0)["ATTITUDE"] == pytest.approx(100.0, rel=0.05)


def test_heartbeat_identity_mode_and_system_status(harness: Harness) -> None:
    hb = harness.api.of_type("HEARTBEAT")[-1]
    assert (hb.type, hb.autopilot, hb.mavlink_version) == (2, 12, 3)
    assert hb.custom_mode == modes.AUTO_LOITER.custom_mode
    assert hb.base_mode == modes.AUTO_LOITER.base_mode(armed=False)
    assert hb.system_status == mavlink.MAV_STATE_STANDBY
    harness.arm()
    harness.run(1.0)
    hb = harness.api.of_type("HEARTBEAT")[-1]
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.system_status == mavlink.MAV_STATE_ACTIVE


@pytest.mark.parametrize(("airframe", "mav_type"), [("plane", 1), ("vtol", 22), ("rover", 10),
                                                     ("hexa", 13), ("octo", 14)])
def test_heartbeat_type_follows_airframe(
    make_harness: HarnessFactory, airframe: str, mav_type: int
) -> None:
    h = make_harness(airframe)
    assert h.api.of_type("HEARTBEAT")[-1].type == mav_type


def test_sys_status_reports_gps_and_prearm_only_once_ready(make_harness: HarnessFactory) -> None:
    h = make_harness(ready=False)
    h.run(2.0)
    before = h.api.of_type("SYS_STATUS")[-1]
    assert not before.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
    assert not before.onboard_control_sensors_present & mavlink.MAV_SYS_STATUS_SENSOR_GPS
    assert h.api.of_type("GLOBAL_POSITION_INT") == []
    h.run(1.5)
    after = h.api.of_type("SYS_STATUS")[-1]
    wanted = (mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
              | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_GPS)
    assert after.onboard_control_sensors_present & wanted == wanted
    assert after.onboard_control_sensors_health & wanted == wanted
    assert after.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
    assert h.gcs.of_type("GPS_RAW_INT")[-1].fix_type == 3


def test_position_messages_match_the_vehicle_state(harness: Harness) -> None:
    harness.vehicle.params.set("MIS_TAKEOFF_ALT", 5.0)
    harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    harness.arm()
    harness.run(6.0)
    v = harness.vehicle
    local = harness.api.of_type("LOCAL_POSITION_NED")[-1]
    assert local.z == pytest.approx(v.truth.position_ned_m[2], abs=0.2)
    glob = harness.api.of_type("GLOBAL_POSITION_INT")[-1]
    assert glob.relative_alt == pytest.approx(-v.truth.position_ned_m[2] * 1000, abs=100)
    assert glob.alt == pytest.approx((v.origin.alt_m - v.truth.position_ned_m[2]) * 1000, abs=100)
    state = harness.api.of_type("EXTENDED_SYS_STATE")[-1]
    assert state.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR
    target = harness.api.of_type("POSITION_TARGET_LOCAL_NED")[-1]
    assert target.z == pytest.approx(-5.0)


def test_battery_drains_with_power_while_flying(harness: Harness) -> None:
    start = harness.vehicle.battery.remaining
    harness.run(5.0)
    idle_drain = start - harness.vehicle.battery.remaining  # disarmed: avionics only
    assert 0 < idle_drain < 2e-4
    harness.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, *([math.nan] * 7))
    harness.arm()
    harness.run(60.0)
    assert harness.vehicle.battery.remaining < start - 0.01
    status = harness.gcs.of_type("BATTERY_STATUS")[-1]
    assert status.battery_remaining == harness.vehicle.battery.remaining_percent
    assert status.voltages[0] == pytest.approx(harness.vehicle.battery.cell_voltage_v * 1000,
                                               abs=20)
    assert status.voltages[4] == 65535  # four cells
    assert status.charge_state == mavlink.MAV_BATTERY_CHARGE_STATE_OK


def test_statustext_longer_than_50_bytes_is_chunked(harness: Harness) -> None:
    text = "SET_POSITION_TARGET_LOCAL_NED coordinate frame 7 unsupported"
    harness.vehicle.announce(mavlink.MAV_SEVERITY_CRITICAL, text)
    chunks = harness.api.of_type("STATUSTEXT")
    assert len(chunks) == 2
    assert chunks[0].id == chunks[1].id != 0
    assert [c.chunk_seq for c in chunks] == [0, 1]
    assert harness.api.texts() == [text]


def test_autopilot_version_reports_px4_v1_16_capabilities(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    version = harness.api.of_type("AUTOPILOT_VERSION")[-1]
    assert version.capabilities == 0xE8FF  # what PX4 v1.16 SITL reports
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_FTP
    assert not version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    assert version.flight_sw_version == version.middleware_sw_version == 0x011000FF  # 1.16.0
    assert version.board_version == 1


@pytest.mark.parametrize("airframe", ["quad", "vtol", "plane", "rover"])
def test_every_streamed_message_has_plausible_contents(make_harness: HarnessFactory,
                                                       airframe: str) -> None:
    h = make_harness(airframe)
    h.run(2.5)
    imu = h.api.of_type("HIGHRES_IMU")[-1]
    assert imu.zacc == pytest.approx(-9.81, abs=0.1)  # at rest: the ground pushes up
    assert 90_000.0 < imu.abs_pressure < 102_000.0  # Pa, as PX4 fills it
    altitude = h.api.of_type("ALTITUDE")[-1]
    assert altitude.altitude_amsl == pytest.approx(h.vehicle.origin.alt_m, abs=0.5)
    assert altitude.altitude_relative == pytest.approx(0.0, abs=0.5)
    odometry = h.api.of_type("ODOMETRY")[-1]
    assert odometry.child_frame_id == mavlink.MAV_FRAME_LOCAL_NED
    assert h.api.of_type("ESTIMATOR_STATUS")[-1].flags & mavlink.ESTIMATOR_POS_HORIZ_ABS
    assert h.api.of_type("DISTANCE_SENSOR")[-1].current_distance < 50
    assert h.api.of_type("MISSION_CURRENT")[-1].total == 0xFFFF  # no mission
    pings = h.api.of_type("PING")
    assert pings[-1].seq > pings[0].seq
    location = h.gcs.of_type("OPEN_DRONE_ID_LOCATION")[-1]
    assert location.latitude == h.api.of_type("GLOBAL_POSITION_INT")[-1].lat
    timesync = h.api.of_type("TIMESYNC")[-1]
    assert (timesync.tc1, timesync.ts1) == (0, pytest.approx(h.vehicle.now_s * 1e9, abs=2e8))


def test_nav_controller_output_only_in_fixed_wing_flight(make_harness: HarnessFactory) -> None:
    h = make_harness("vtol")
    h.run(1.0)
    assert h.api.of_type("NAV_CONTROLLER_OUTPUT") == []
    h.model.request_transition(to_fixed_wing=True, immediate=True)
    h.api.clear()
    h.run(1.0)
    assert len(h.api.of_type("NAV_CONTROLLER_OUTPUT")) == pytest.approx(10, abs=1)


def test_timesync_request_is_answered_with_the_vehicle_clock(harness: Harness) -> None:
    harness.api.clear()
    harness.deliver(mavlink.MAVLink_timesync_message(0, 123_456_789))
    (answer,) = harness.api.of_type("TIMESYNC")
    assert answer.ts1 == 123_456_789
    assert answer.tc1 == pytest.approx(harness.vehicle.now_s * 1e9, abs=1e7)
    harness.deliver(mavlink.MAVLink_timesync_message(5, 6))  # an answer: nothing more
    assert len(harness.api.of_type("TIMESYNC")) == 1


def test_get_message_interval_reports_this_links_interval(harness: Harness) -> None:
    harness.command_long(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE)
    harness.command_long(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE,
                         link=harness.gcs)
    harness.command_long(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL,
                         mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
    api = [(m.message_id, m.interval_us) for m in harness.api.of_type("MESSAGE_INTERVAL")]
    assert api == [(mavlink.MAVLINK_MSG_ID_ATTITUDE, 10_000),
                   (mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, 0)]  # 100 Hz; not streamed
    (gcs,) = harness.gcs.of_type("MESSAGE_INTERVAL")
    assert gcs.interval_us == 20_000  # 50 Hz on SITL's GCS link
    assert harness.last_ack(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL) == mavlink.MAV_RESULT_ACCEPTED


def test_a_message_due_on_both_links_is_built_once_and_requests_are_fresh(
    harness: Harness,
) -> None:
    factory = harness.vehicle.messages
    streamed = factory.build_streamed(mavlink.MAVLINK_MSG_ID_CURRENT_MODE)
    assert factory.build_streamed(mavlink.MAVLINK_MSG_ID_CURRENT_MODE) is streamed
    harness.set_mode(modes.AUTO_RTL)  # same sim time: a request sees the new mode
    requested = factory.build(mavlink.MAVLINK_MSG_ID_CURRENT_MODE)
    assert requested.custom_mode == modes.AUTO_RTL.custom_mode != streamed.custom_mode
