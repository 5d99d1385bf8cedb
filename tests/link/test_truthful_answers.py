"""Answers that say what the vehicle did: a repeated setpoint renews the stream without an
extra send, a VTOL transition on a multicopter is refused at once, a mode PX4 accepts but
does not enter is asked for again, and a take-off after PX4 disarmed itself arms again."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.commands import CommandOutcome, CommandResult
from server.link.codec.setpoints import PositionNed
from tests.link.conftest import ScriptedSession, open_sim, wait_for

STREAM_RATE_HZ = 50.0
RENEWALS = 40
MAV_TYPE_VTOL_FIXEDROTOR = 22  # a standard VTOL (the dialect still calls it RESERVED2)


def _setpoint_times(session: ScriptedSession) -> list[float]:
    return [t for t, m in session.peer.received if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]


async def test_a_repeated_setpoint_renews_the_stream_without_an_extra_send(
    scripted: ScriptedSession,
) -> None:
    scripted.peer.send(mavlink.MAVLink_local_position_ned_message(0, 0, 0, -5, 0, 0, 0))
    await wait_for(lambda: scripted.vehicle.snapshot().position_ned is not None)
    vehicle = scripted.vehicle
    vehicle.stream_rate_hz = STREAM_RATE_HZ
    setpoint = PositionNed(1.0, 2.0, -5.0, 90.0)
    await vehicle.set_setpoint(setpoint)
    await wait_for(lambda: len(_setpoint_times(scripted)) == 1, 1.0, "the first send")

    for _ in range(RENEWALS):
        await vehicle.set_setpoint(setpoint)
        # paced by the stream itself: the next PUT goes once the peer got one more send
        # (with an extra send per PUT, this loop would run through without waiting)
        received = len(_setpoint_times(scripted))
        await wait_for(lambda n=received: len(_setpoint_times(scripted)) > n, 1.0, "a tick")

    times = _setpoint_times(scripted)
    period_s = 1.0 / STREAM_RATE_HZ
    scheduled = 1 + math.floor((times[-1] - times[0]) / period_s + 0.5)
    # one send per renewal's wait; a loaded machine may let a second tick land before the
    # wait sees the first, so the bound below (the schedule) is what pins "no extra send"
    assert len(times) >= RENEWALS + 1
    # every send is a scheduled tick: as many as the time they span allows, and no more
    assert len(times) <= scheduled + 1, (len(times), scheduled)
    assert times[-1] - times[0] >= (RENEWALS - 2) * period_s
    vehicle.offboard.stop_stream("renewals over")
    # the figures are the sender's own send times, reported after the sends
    await wait_for(
        lambda: vehicle.stream_stats().sent == len(_setpoint_times(scripted)), 2.0,
        "every send in the stream's figures")


async def test_vtol_transition_on_a_multicopter_is_refused_at_once(
    scripted: ScriptedSession,
) -> None:
    result = await scripted.vehicle.vtol_transition(to_fixed_wing=True)

    assert result.outcome is CommandOutcome.FAILED
    assert result.reason == "not a VTOL (QUADROTOR): PX4 does not answer a transition on it"
    assert result.elapsed_ms < 50
    assert scripted.peer.commands(mavlink.MAV_CMD_DO_VTOL_TRANSITION) == []


async def test_vtol_transition_goes_out_once_the_vehicle_says_it_is_a_vtol(
    scripted: ScriptedSession,
) -> None:
    scripted.peer.mav_type = MAV_TYPE_VTOL_FIXEDROTOR
    scripted.peer.heartbeat()
    await wait_for(lambda: scripted.vehicle.mav_type == MAV_TYPE_VTOL_FIXEDROTOR)

    result = await scripted.vehicle.vtol_transition(to_fixed_wing=True, timeout_s=0.1)

    assert result.outcome is CommandOutcome.TIMEOUT  # the scripted peer never answers
    assert scripted.peer.commands(mavlink.MAV_CMD_DO_VTOL_TRANSITION)


async def _start_offboard_losing(requests_lost: int) -> tuple[CommandResult, bool]:
    """start_offboard on the sim while it loses the next OFFBOARD requests (acked, yet the
    vehicle stays in Hold): the result, and whether the stream still runs."""
    async with open_sim(speed=5.0) as session:
        vehicle = session.vehicle
        vehicle.mode_confirm_timeout_s = 1.0
        vehicle.offboard_prestream_s = 0.2
        commander = session.sim.instances[0].vehicle.commander
        commander.offboard_requests_lost = requests_lost

        result = await vehicle.start_offboard()

        assert commander.offboard_requests_lost == 0
        assert (vehicle.snapshot().mode == "OFFBOARD") is result.ok
        return result, vehicle.streamer_active


async def test_offboard_accepted_but_not_entered_is_asked_for_once_more() -> None:
    result, streaming = await _start_offboard_losing(1)

    assert result.ok, result
    assert streaming


async def test_offboard_asked_again_keeps_the_stream_a_mode_change_would_have_stopped() -> None:
    """Flying in OFFBOARD, a new start whose first ask PX4 acks but ends in HOLD (as when a
    takeoff ends just then): the stream goes on through the second ask, which PX4 takes."""
    async with open_sim(speed=2.0) as session:
        vehicle = session.vehicle
        assert (await vehicle.takeoff(3.0)).ok  # arms and climbs
        await wait_for(lambda: vehicle.snapshot().mode == "HOLD", 20.0, "the takeoff done")
        assert (await vehicle.start_offboard()).ok  # the stream engaged in OFFBOARD
        session.sim.instances[0].vehicle.commander.offboard_requests_lost = 1
        here = vehicle.snapshot().position_ned
        assert here is not None

        result = await vehicle.start_offboard(PositionNed(here.north_m + 2, here.east_m, -3.0))

        assert result.ok, result
        assert vehicle.streamer_active
        assert vehicle.snapshot().mode == "OFFBOARD"


async def test_offboard_lost_twice_is_not_confirmed_with_the_mode_observed() -> None:
    result, streaming = await _start_offboard_losing(2)

    assert result.outcome is CommandOutcome.NOT_CONFIRMED
    assert result.reason == "accepted twice, but the vehicle still reports HOLD"
    assert result.result_code == mavlink.MAV_RESULT_ACCEPTED
    assert result.elapsed_ms >= 2000
    assert not streaming


async def test_takeoff_after_px4_disarmed_itself_arms_again_and_climbs() -> None:
    async with open_sim(speed=5.0) as session:
        vehicle = session.vehicle
        assert (await vehicle.arm()).ok
        # PX4 disarms a vehicle left armed on the ground (COM_DISARM_PRFLT, 10 sim s)
        await wait_for(lambda: vehicle.snapshot().armed, 3.0, "armed")
        await wait_for(lambda: not vehicle.snapshot().armed, 6.0, "PX4's own disarm")

        result = await vehicle.takeoff(3.0)

        assert result.ok, result
        assert result.command == "MAV_CMD_NAV_TAKEOFF"
        assert vehicle.snapshot().armed


async def test_takeoff_before_px4_is_ready_answers_the_refused_arming_and_leaves_no_takeoff(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """PX4 takes NAV_TAKEOFF while disarmed, ready or not, and refuses the arming after it:
    the answer is that refusal with PX4's reason, and the vehicle is back in the mode it was
    in (left in TAKEOFF, the pilot's next Arm would start a climb)."""
    monkeypatch.setattr("sim.vehicle.READY_TIME_S", math.inf)  # a position that never comes
    async with open_sim(speed=5.0, position=False) as session:
        vehicle = session.vehicle
        simulated = session.sim.instances[0].vehicle
        await wait_for(lambda: vehicle.snapshot().mode == "HOLD", 5.0, "the first mode")
        changes_before = simulated.commander.mode_changes

        result = await vehicle.takeoff(3.0)

        assert result.outcome is CommandOutcome.TEMPORARILY_REJECTED, result
        assert result.command == "MAV_CMD_COMPONENT_ARM_DISARM"
        assert result.reason is not None
        assert result.reason.startswith("Arming denied: Resolve system health failures first")
        assert not vehicle.snapshot().armed
        # PX4 took the takeoff (one mode change) and HOLD again (the other)
        assert simulated.commander.mode_changes == changes_before + 2
        assert simulated.mode_name == "AUTO_LOITER"
        await wait_for(lambda: vehicle.snapshot().mode == "HOLD", 3.0, "HOLD reported")


async def test_takeoff_right_after_arming_is_confirmed_by_the_climb() -> None:
    async with open_sim(speed=5.0) as session:
        vehicle = session.vehicle
        assert (await vehicle.arm()).ok
        result = await vehicle.takeoff(3.0)

        assert result.ok, result
        assert vehicle.snapshot().armed


async def test_takeoff_while_disarmed_waits_for_the_takeoff_mode_before_arming(
    scripted: ScriptedSession,
) -> None:
    scripted.peer.accept_commands()  # acks everything, never reports a mode change

    result = await scripted.vehicle.takeoff()

    assert result.outcome is CommandOutcome.NOT_CONFIRMED
    assert result.reason is not None
    assert result.reason.startswith("accepted, but the vehicle still reports")
    sent = [m.command for _, m in scripted.peer.received if m.get_type() == "COMMAND_LONG"]
    assert mavlink.MAV_CMD_NAV_TAKEOFF in sent
    assert mavlink.MAV_CMD_COMPONENT_ARM_DISARM not in sent
