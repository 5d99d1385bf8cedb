"""Vehicle operations against a scripted PX4: what goes on the wire, and what confirms it."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.commands import CommandOutcome
from server.link.plugins.telemetry_requests import DEFAULT_TELEMETRY_RATES_HZ
from tests.link.conftest import ScriptedSession, open_scripted, wait_for

HOME_ALT_M = 489.4


def _send_home(session: ScriptedSession) -> None:
    session.peer.send(
        mavlink.MAVLink_home_position_message(
            473977420, 85455940, round(HOME_ALT_M * 1000), 0, 0, 0, [1, 0, 0, 0], 0, 0, 0
        )
    )


async def test_set_mode_resolves_only_when_the_vehicle_reports_the_mode(
    scripted: ScriptedSession,
) -> None:
    scripted.peer.accept_commands(mode_report_delay_s=0.3)

    result = await scripted.vehicle.set_mode("POSCTL")

    assert result.ok
    assert result.command == "SET_MODE:POSCTL"
    assert result.elapsed_ms >= 290
    assert scripted.vehicle.snapshot().mode == "POSCTL"


async def test_set_mode_accepted_but_never_reported_is_not_confirmed(
    scripted: ScriptedSession,
) -> None:
    scripted.peer.on_command = lambda m: scripted.peer.ack(m.command, 0)

    result = await scripted.vehicle.set_mode("LAND")

    assert result.outcome is CommandOutcome.NOT_CONFIRMED
    assert result.reason is not None
    assert "HOLD" in result.reason


async def test_set_mode_sends_custom_bit_armed_bit_main_and_sub(scripted: ScriptedSession) -> None:
    scripted.peer.base_mode = 1 | 128
    scripted.peer.heartbeat()
    await wait_for(lambda: scripted.vehicle.snapshot().armed)
    scripted.peer.accept_commands()

    await scripted.vehicle.set_mode("RTL")

    (sent,) = scripted.peer.commands(mavlink.MAV_CMD_DO_SET_MODE)
    assert (sent.param1, sent.param2, sent.param3) == (129, 4, 5)


async def test_reposition_is_a_command_int_in_deg_e7_with_change_mode_and_home_altitude(
    scripted: ScriptedSession,
) -> None:
    _send_home(scripted)
    await wait_for(lambda: scripted.vehicle.snapshot().home is not None)
    scripted.peer.accept_commands()

    result = await scripted.vehicle.reposition(
        47.3979421, 8.5461941, alt_rel_m=10, ground_speed_m_s=3, yaw_deg=90
    )

    (sent,) = scripted.peer.commands(mavlink.MAV_CMD_DO_REPOSITION)
    assert result.ok
    assert sent.get_type() == "COMMAND_INT"
    assert sent.frame == mavlink.MAV_FRAME_GLOBAL
    assert (sent.x, sent.y) == (473979421, 85461941)
    assert sent.z == pytest.approx(HOME_ALT_M + 10)
    assert sent.param1 == 3
    assert sent.param2 == mavlink.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
    assert sent.param4 == pytest.approx(math.pi / 2)


async def test_takeoff_altitude_is_converted_above_home_and_nan_means_px4_default(
    scripted: ScriptedSession,
) -> None:
    _send_home(scripted)
    await wait_for(lambda: scripted.vehicle.snapshot().home is not None)
    scripted.peer.accept_commands()

    await scripted.vehicle.takeoff(5.0)
    await scripted.vehicle.takeoff()

    first, second = scripted.peer.commands(mavlink.MAV_CMD_NAV_TAKEOFF)
    assert first.param7 == pytest.approx(HOME_ALT_M + 5.0)
    assert math.isnan(second.param7)


async def test_vtol_transition_resolves_on_vtol_state_not_on_the_ack(
    scripted: ScriptedSession,
) -> None:
    peer = scripted.peer
    peer.send(mavlink.MAVLink_extended_sys_state_message(3, 2))  # a VTOL, in MC
    await wait_for(lambda: scripted.vehicle.snapshot().vtol_state == "MC")

    def transition(msg: mavlink.MAVLink_message) -> None:
        peer.ack(msg.command, 0)
        peer.send(mavlink.MAVLink_extended_sys_state_message(1, 2))  # TRANSITION_TO_FW
        peer.send_later(0.3, mavlink.MAVLink_extended_sys_state_message(4, 2))  # FW

    peer.on_command = transition
    result = await scripted.vehicle.vtol_transition(to_fixed_wing=True)

    assert result.ok
    assert result.elapsed_ms >= 290
    assert scripted.vehicle.snapshot().vtol_state == "FW"
    (sent,) = peer.commands(mavlink.MAV_CMD_DO_VTOL_TRANSITION)
    assert sent.param1 == mavlink.MAV_VTOL_STATE_FW


async def test_vtol_transition_that_never_completes_is_not_confirmed(
    scripted: ScriptedSession,
) -> None:
    scripted.peer.send(mavlink.MAVLink_extended_sys_state_message(4, 2))  # a VTOL, in FW
    await wait_for(lambda: scripted.vehicle.snapshot().vtol_state == "FW")
    scripted.peer.on_command = lambda m: scripted.peer.ack(m.command, 0)

    result = await scripted.vehicle.vtol_transition(to_fixed_wing=False, timeout_s=0.2)

    assert result.outcome is CommandOutcome.NOT_CONFIRMED


async def test_gps_origin_is_confirmed_by_the_gps_global_origin_echo(
    scripted: ScriptedSession,
) -> None:
    peer = scripted.peer

    def echo(msg: mavlink.MAVLink_message) -> None:
        if msg.get_type() == "SET_GPS_GLOBAL_ORIGIN":
            peer.send(mavlink.MAVLink_gps_global_origin_message(
                msg.latitude, msg.longitude, msg.altitude))  # fmt: skip

    peer.on_message = echo
    result = await scripted.vehicle.set_gps_origin(47.0, 8.0, 500.25)

    assert result.ok
    assert result.command == "SET_GPS_GLOBAL_ORIGIN"
    (sent,) = peer.messages("SET_GPS_GLOBAL_ORIGIN")
    assert (sent.latitude, sent.longitude, sent.altitude) == (470000000, 80000000, 500250)


async def test_gps_origin_without_echo_times_out(scripted: ScriptedSession) -> None:
    result = await scripted.vehicle.set_gps_origin(47.0, 8.0, 500.0)

    assert result.outcome is CommandOutcome.TIMEOUT
    assert len(scripted.peer.messages("SET_GPS_GLOBAL_ORIGIN")) == 4


async def test_set_home_here_uses_param1_one(scripted: ScriptedSession) -> None:
    scripted.peer.accept_commands()

    assert (await scripted.vehicle.set_home()).ok

    (sent,) = scripted.peer.commands(mavlink.MAV_CMD_DO_SET_HOME)
    assert sent.param1 == 1


async def test_telemetry_is_requested_on_connection_and_refusals_are_noted() -> None:
    async with open_scripted() as session:
        peer = session.peer

        def answer(msg: mavlink.MAVLink_message) -> None:
            refused = msg.param1 == mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW
            peer.ack(msg.command, mavlink.MAV_RESULT_FAILED if refused else 0)

        peer.on_command = answer
        await wait_for(
            lambda: len(peer.commands(mavlink.MAV_CMD_REQUEST_MESSAGE)) == 2,
            what="telemetry requests",
        )
        await session.vehicle_heard_all()  # the answers to them

        intervals = {
            int(m.param1): m.param2 for m in peer.commands(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL)
        }
        assert set(intervals) == set(DEFAULT_TELEMETRY_RATES_HZ)
        assert intervals[mavlink.MAVLINK_MSG_ID_CURRENT_MODE] <= 200_000  # >= 5 Hz
        # PX4's 50 Hz onboard streams nothing reads are asked off (interval -1)
        assert intervals[mavlink.MAVLINK_MSG_ID_HIGHRES_IMU] == -1
        assert intervals[mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION] == -1
        assert session.vehicle.snapshot().telemetry_refused == ("SERVO_OUTPUT_RAW",)


async def test_vtol_transition_that_falls_back_to_multicopter_fails(
    scripted: ScriptedSession,
) -> None:
    peer = scripted.peer
    peer.send(mavlink.MAVLink_extended_sys_state_message(3, 2))  # MC
    await wait_for(lambda: scripted.vehicle.snapshot().vtol_state == "MC")

    def quadchute(msg: mavlink.MAVLink_message) -> None:
        peer.ack(msg.command, 0)
        peer.send(mavlink.MAVLink_extended_sys_state_message(1, 2))  # TRANSITION_TO_FW
        peer.send_later(0.1, mavlink.MAVLink_extended_sys_state_message(3, 2))  # MC again

    peer.on_command = quadchute
    result = await scripted.vehicle.vtol_transition(to_fixed_wing=True, timeout_s=5.0)

    assert result.outcome is CommandOutcome.FAILED
    assert result.elapsed_ms < 1000


async def test_set_home_at_a_place_is_a_command_int_in_deg_e7(scripted: ScriptedSession) -> None:
    scripted.peer.accept_commands()

    assert (await scripted.vehicle.set_home(47.5, 8.25, 500.0)).ok

    (sent,) = scripted.peer.commands(mavlink.MAV_CMD_DO_SET_HOME)
    assert sent.get_type() == "COMMAND_INT"
    assert (sent.param1, sent.x, sent.y, sent.z) == (0, 475000000, 82500000, 500.0)


async def test_telemetry_is_requested_again_when_the_vehicle_comes_back() -> None:
    async with open_scripted() as session:
        peer = session.peer
        peer.accept_commands()
        requests = len(DEFAULT_TELEMETRY_RATES_HZ)

        def first_tries() -> int:  # retries of an early unanswered request do not count
            sent = peer.commands(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL)
            return sum(1 for m in sent if m.confirmation == 0)

        await wait_for(lambda: first_tries() == requests, what="first requests")
        session.vehicle.set_connected(False)
        session.vehicle.set_connected(True)

        await wait_for(lambda: first_tries() == 2 * requests, what="re-requests")
