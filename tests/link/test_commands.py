"""Command protocol against a scripted PX4 peer: retries, IN_PROGRESS, PX4's double ACK,
late and foreign ACKs, refusal reasons, one command per id in flight."""

from __future__ import annotations

import asyncio
import math

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.commands import CommandOutcome
from tests.link.conftest import ScriptedSession, drain, wait_for
from tests.waiting import holds_for

ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
SET_MODE = mavlink.MAV_CMD_DO_SET_MODE
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
IN_PROGRESS = mavlink.MAV_RESULT_IN_PROGRESS


async def test_unanswered_command_times_out_after_exactly_four_sends(
    scripted: ScriptedSession,
) -> None:
    result = await scripted.vehicle.arm()
    # nothing more may follow the timeout (longer than the 0.1 s retry interval)
    await holds_for(lambda: len(scripted.peer.commands(ARM)) == 4, 0.15, "no send after it")

    sent = scripted.peer.commands(ARM)
    assert result.outcome is CommandOutcome.TIMEOUT
    assert result.result_code is None
    assert [m.confirmation for m in sent] == [0, 1, 2, 3]
    assert 0.35 <= result.elapsed_ms / 1000 < 1.0  # 4 tries of 0.1 s


async def test_command_long_targets_the_vehicle_and_leaves_unused_params_nan(
    scripted: ScriptedSession,
) -> None:
    scripted.peer.on_command = lambda m: scripted.peer.ack(m.command, ACCEPTED)

    result = await scripted.vehicle.land()

    (sent,) = scripted.peer.commands(mavlink.MAV_CMD_NAV_LAND)
    assert result.ok
    assert result.command == "MAV_CMD_NAV_LAND"
    assert (sent.target_system, sent.target_component) == (1, 1)
    assert all(math.isnan(getattr(sent, f"param{i}")) for i in range(1, 8))


async def test_in_progress_is_not_final_and_stops_retries(scripted: ScriptedSession) -> None:
    peer = scripted.peer
    events = scripted.vehicle.subscribe_events()

    def answer(msg: mavlink.MAVLink_message) -> None:
        peer.ack(msg.command, IN_PROGRESS, progress=40)
        peer.ack(msg.command, ACCEPTED, delay_s=0.35)

    peer.on_command = answer
    result = await scripted.vehicle.arm()

    assert result.outcome is CommandOutcome.ACCEPTED
    assert len(peer.commands(ARM)) == 1  # no retry while the vehicle says it is working
    progress = [e.data for e in drain(events) if e.data.get("outcome") == "IN_PROGRESS"]
    assert progress
    assert progress[0]["progress"] == 40


async def test_in_progress_without_a_final_answer_times_out_without_retries(
    scripted: ScriptedSession,
) -> None:
    peer = scripted.peer
    scripted.vehicle.commands.in_progress_timeout_s = 0.3
    peer.on_command = lambda m: peer.ack(m.command, IN_PROGRESS, progress=10)

    result = await scripted.vehicle.arm()

    assert result.outcome is CommandOutcome.TIMEOUT
    assert result.elapsed_ms >= 290
    assert len(peer.commands(ARM)) == 1


async def test_second_ack_of_set_mode_replaces_the_first(scripted: ScriptedSession) -> None:
    peer = scripted.peer

    def px4_double_ack(msg: mavlink.MAVLink_message) -> None:
        peer.ack(msg.command, ACCEPTED)
        peer.ack(msg.command, TEMPORARILY_REJECTED, delay_s=0.03)

    peer.on_command = px4_double_ack
    result = await scripted.vehicle.set_mode("OFFBOARD")

    assert result.outcome is CommandOutcome.TEMPORARILY_REJECTED
    assert result.result_code == TEMPORARILY_REJECTED
    assert result.command == "SET_MODE:OFFBOARD"


async def test_late_ack_after_timeout_is_ignored(scripted: ScriptedSession) -> None:
    peer = scripted.peer
    first = await scripted.vehicle.arm()
    peer.ack(ARM, ACCEPTED)  # the answer to the timed-out command arrives now
    await scripted.vehicle_heard_all()
    second = await scripted.vehicle.arm()

    assert first.outcome is CommandOutcome.TIMEOUT
    assert second.outcome is CommandOutcome.TIMEOUT
    assert len(peer.commands(ARM)) == 8


async def test_acks_from_another_system_component_or_for_another_gcs_are_ignored(
    scripted: ScriptedSession,
) -> None:
    peer = scripted.peer
    peer.heartbeat(sysid=2)  # make system 2 a known vehicle on the same link
    await wait_for(lambda: 2 in scripted.link.vehicles, what="second vehicle")

    def foreign_acks(msg: mavlink.MAVLink_message) -> None:
        peer.ack(msg.command, ACCEPTED, sysid=2)
        peer.ack(msg.command, ACCEPTED, compid=100)
        peer.ack(msg.command, ACCEPTED, target_system=42)

    peer.on_command = foreign_acks
    result = await scripted.vehicle.arm()

    assert result.outcome is CommandOutcome.TIMEOUT


async def test_refusal_carries_the_statustext_that_explains_it(scripted: ScriptedSession) -> None:
    peer = scripted.peer

    def refuse(msg: mavlink.MAVLink_message) -> None:
        peer.ack(msg.command, TEMPORARILY_REJECTED)
        # PX4 may publish its report just after the ACK
        peer.send_later(
            0.01,
            mavlink.MAVLink_statustext_message(
                mavlink.MAV_SEVERITY_CRITICAL, b"Arming denied: no offboard signal"
            ),
        )

    peer.on_command = refuse
    result = await scripted.vehicle.arm()

    assert result.outcome is CommandOutcome.TEMPORARILY_REJECTED
    assert result.reason == "Arming denied: no offboard signal"
    assert not result.ok


async def test_second_command_with_same_id_waits_for_the_first(scripted: ScriptedSession) -> None:
    peer = scripted.peer
    peer.on_command = lambda m: peer.ack(m.command, ACCEPTED, delay_s=0.05)

    first, second = await asyncio.gather(scripted.vehicle.arm(), scripted.vehicle.disarm())

    received = [
        (t, m) for t, m in peer.received if m.get_type() == "COMMAND_LONG" and m.command == ARM
    ]
    assert first.ok
    assert second.ok
    assert [m.param1 for _, m in received] == [1.0, 0.0]
    assert received[1][0] - received[0][0] >= 0.04  # sent only after the first ACK


async def test_pending_command_ends_as_link_lost_when_vehicle_goes_silent(
    scripted: ScriptedSession,
) -> None:
    scripted.vehicle.commands.timeout_s = 5.0
    task = asyncio.ensure_future(scripted.vehicle.arm())
    await wait_for(lambda: bool(scripted.peer.commands(ARM)))
    scripted.vehicle.set_connected(False)

    result = await asyncio.wait_for(task, 1.0)

    assert result.outcome is CommandOutcome.LINK_LOST
