"""Offboard through the Vehicle: pre-streaming, mode confirmation, staying in offboard
after a failsafe blip, stopping when the user picks another mode, setpoint refusals."""

from __future__ import annotations

import time

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.setpoint_checks import SetpointRejected
from server.link.codec.setpoints import OffsetBody, PositionGlobal, PositionNed, VelocityNed
from tests.link.conftest import ScriptedSession, wait_for
from tests.waiting import holds_for

OFFBOARD = 0x60000
POSCTL = 0x30000
HOLD = 0x3040000


async def _at(
    session: ScriptedSession, north_m: float, east_m: float, down_m: float, yaw_deg: float
) -> None:
    session.peer.send(
        mavlink.MAVLink_local_position_ned_message(0, north_m, east_m, down_m, 0, 0, 0)
    )
    session.peer.send(
        mavlink.MAVLink_attitude_message(0, 0, 0, yaw_deg / 57.29577951308232, 0, 0, 0)
    )
    await wait_for(lambda: session.vehicle.snapshot().attitude is not None)


async def _ready_for_offboard(session: ScriptedSession, prestream_s: float = 0.1) -> None:
    """5 m up facing north, a peer that accepts every command, a short pre-stream."""
    await _at(session, 0.0, 0.0, -5.0, 0.0)
    session.peer.accept_commands()
    session.vehicle.offboard_prestream_s = prestream_s


def _setpoints(session: ScriptedSession) -> list[tuple[float, mavlink.MAVLink_message]]:
    return [
        (t, m) for t, m in session.peer.received if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
    ]


async def test_start_offboard_streams_a_second_then_switches_and_holds_here(
    scripted: ScriptedSession,
) -> None:
    await _at(scripted, 3.0, 4.0, -10.0, 90.0)
    scripted.peer.accept_commands()

    result = await scripted.vehicle.start_offboard()

    assert result.ok
    assert scripted.vehicle.snapshot().mode == "OFFBOARD"
    (mode_cmd,) = [
        (t, m)
        for t, m in scripted.peer.received
        if m.get_type() == "COMMAND_LONG" and m.command == 176
    ]
    stream = _setpoints(scripted)
    assert mode_cmd[0] - stream[0][0] >= 0.95
    assert len([t for t, _ in stream if t < mode_cmd[0]]) >= 18  # 20 Hz before the switch
    first = stream[0][1]
    assert (first.x, first.y, first.z, first.type_mask) == (3.0, 4.0, -10.0, 2552)
    assert first.yaw == pytest.approx(1.5708, abs=1e-3)


async def test_stream_survives_a_failsafe_blip_and_stops_when_the_user_picks_a_mode(
    scripted: ScriptedSession,
) -> None:
    await _ready_for_offboard(scripted)
    assert (await scripted.vehicle.start_offboard()).ok

    scripted.peer.report_mode(POSCTL, OFFBOARD)  # PX4's offboard-loss fallback
    await scripted.vehicle_heard_all()
    await holds_for(lambda: scripted.vehicle.streamer_active, 0.2, "the stream in the failsafe")

    scripted.peer.report_mode(HOLD, HOLD)  # the user switched, e.g. from an RC
    await wait_for(lambda: not scripted.vehicle.streamer_active, 1.0, "stream stopped")
    assert scripted.vehicle.snapshot().setpoint is None


async def test_stop_offboard_switches_mode_then_stops_streaming(scripted: ScriptedSession) -> None:
    await _ready_for_offboard(scripted)
    await scripted.vehicle.start_offboard(VelocityNed(1, 0, 0, yaw_deg=0))

    result = await scripted.vehicle.stop_offboard()

    assert result.ok
    assert scripted.vehicle.snapshot().mode == "HOLD"
    assert not scripted.vehicle.streamer_active


async def test_offboard_refused_stops_the_stream_it_started(scripted: ScriptedSession) -> None:
    await _at(scripted, 0.0, 0.0, -5.0, 0.0)
    scripted.peer.on_command = lambda m: scripted.peer.ack(m.command, 1)
    scripted.vehicle.offboard_prestream_s = 0.1

    result = await scripted.vehicle.start_offboard()

    assert not result.ok
    assert not scripted.vehicle.streamer_active


async def test_offset_body_setpoint_goes_out_as_local_ned_target(scripted: ScriptedSession) -> None:
    await _at(scripted, 10.0, 0.0, -5.0, 90.0)

    sent = await scripted.vehicle.set_setpoint(OffsetBody(forward_m=2, right_m=0, down_m=-1))
    await wait_for(lambda: bool(_setpoints(scripted)))

    msg = _setpoints(scripted)[0][1]
    assert sent.frame == msg.coordinate_frame == 1
    assert (msg.x, msg.y, msg.z) == pytest.approx((10.0, 2.0, -6.0), abs=1e-5)
    assert scripted.vehicle.snapshot().setpoint == {
        "type": "position_ned",
        "north_m": pytest.approx(10.0),
        "east_m": pytest.approx(2.0),
        "down_m": -6.0,
        "yaw_deg": pytest.approx(90.0),
    }


async def test_setpoint_outside_the_envelope_is_refused_and_not_sent(
    scripted: ScriptedSession,
) -> None:
    await _at(scripted, 0.0, 0.0, -5.0, 0.0)
    scripted.vehicle.envelope.max_alt_rel_m = 50.0

    with pytest.raises(SetpointRejected) as info:
        await scripted.vehicle.set_setpoint(PositionNed(0, 0, -60))
    await scripted.peer_heard_all()

    assert info.value.limit == 50.0
    assert not _setpoints(scripted)
    assert not scripted.vehicle.streamer_active


async def test_hold_position_setpoint_works_even_outside_the_envelope(
    scripted: ScriptedSession,
) -> None:
    await _at(scripted, 0.0, 0.0, -80.0, 0.0)
    scripted.vehicle.envelope.max_alt_rel_m = 50.0

    sent = await scripted.vehicle.hold_position_setpoint()

    assert sent.setpoint == PositionNed(0.0, 0.0, -80.0, 0.0)
    assert scripted.vehicle.streamer_active


async def test_every_offboard_start_after_a_stop_streams_first_again(
    scripted: ScriptedSession,
) -> None:
    await _ready_for_offboard(scripted, prestream_s=0.3)
    await scripted.vehicle.start_offboard()
    await scripted.vehicle.stop_offboard()
    await scripted.peer_heard_all()  # the last frames of the first stream have landed
    stopped_at = time.monotonic()

    assert (await scripted.vehicle.start_offboard()).ok

    restart = next(t for t, _ in _setpoints(scripted) if t > stopped_at)
    (second_switch,) = [
        t for t, m in scripted.peer.commands_at(176) if m.param2 == 6 and t > stopped_at
    ]
    assert second_switch - restart >= 0.28


async def test_global_setpoint_before_a_global_position_is_refused(
    scripted: ScriptedSession,
) -> None:
    with pytest.raises(SetpointRejected, match="no global position"):
        await scripted.vehicle.set_setpoint(PositionGlobal(47.4, 8.5, 10.0, "relative"))

    scripted.peer.send(
        mavlink.MAVLink_global_position_int_message(
            0, 473977420, 85455940, 492400, 3000, 0, 0, 0, 0
        )
    )
    await wait_for(lambda: scripted.vehicle.snapshot().global_position is not None)
    sent = await scripted.vehicle.set_setpoint(PositionGlobal(47.3978, 8.5456, 10.0, "relative"))
    assert sent.frame == 6
