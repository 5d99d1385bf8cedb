"""PX4's events end to end against the simulated vehicle: its EVENTs, the metadata the link
fetches over MAVLink FTP, and the decoded texts as refusal reasons, WS events and log lines,
for an arming refusal, a mode refusal and a failsafe."""

from __future__ import annotations

from server.link.codec.commands import CommandOutcome
from server.link.codec.setpoints import PositionNed
from server.link.vehicle import Vehicle
from tests.link.conftest import SimSession, arm_as_sent, drain, open_sim, wait_for

SPEED = 5.0  # sim seconds per wall second
NO_OFFBOARD_SIGNAL = "No offboard signal"


async def _decoding(vehicle: Vehicle) -> None:
    await wait_for(lambda: vehicle.px4_events.decoder is not None, 10.0, "events metadata")


async def _hovering(session: SimSession) -> None:
    vehicle = session.vehicle
    assert (await vehicle.arm()).ok
    assert (await vehicle.takeoff(3.0)).ok
    await wait_for(lambda: vehicle.snapshot().mode == "HOLD", 30 / SPEED, "takeoff done")


async def test_arming_refusal_reason_is_px4s_text_with_the_failing_check() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        await _decoding(vehicle)
        assert (await vehicle.set_mode("OFFBOARD")).ok  # disarmed: accepted

        result = await arm_as_sent(vehicle)

        assert result.outcome is CommandOutcome.TEMPORARILY_REJECTED
        assert result.reason == (
            f"Arming denied: Resolve system health failures first: {NO_OFFBOARD_SIGNAL}"
        )


async def test_mode_refusal_names_the_missing_offboard_signal() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        await _decoding(vehicle)
        await _hovering(session)

        result = await vehicle.set_mode("OFFBOARD")  # armed, no setpoint stream

        assert result.outcome is CommandOutcome.TEMPORARILY_REJECTED
        assert result.reason == (
            f"Switching to mode 'Offboard' is currently not possible: {NO_OFFBOARD_SIGNAL}"
        )
        assert vehicle.snapshot().mode == "HOLD"


async def test_offboard_loss_failsafe_is_a_px4_event_and_a_log_line() -> None:
    async with open_sim(speed=SPEED) as session:
        vehicle = session.vehicle
        await _decoding(vehicle)
        await _hovering(session)
        here = vehicle.snapshot().position_ned
        assert here is not None
        assert (await vehicle.start_offboard(PositionNed(here.north_m, here.east_m,
                                                         here.down_m, yaw_deg=0))).ok
        events = vehicle.subscribe_events(maxsize=1024)

        vehicle.offboard.close()  # the stream stops: COM_OBL_RC_ACT 0, Position
        await wait_for(lambda: vehicle.snapshot().mode == "POSCTL", 5.0, "failsafe")
        text = "Failsafe activated: switching to Position mode"
        await wait_for(lambda: any(m.text == text for m in vehicle.snapshot().statustext),
                       2.0, "the failsafe in the log")  # fmt: skip

        failsafe = "commander_failsafe_enter_generic"
        failsafes = [e.data for e in drain(events)
                     if e.kind == "px4_event" and e.data["name"] == failsafe]  # fmt: skip
        assert [(f["text"], f["log_level"]) for f in failsafes] == [(text, "CRITICAL")]
        log = [(m.severity, m.text) for m in vehicle.snapshot().statustext]
        assert ("CRITICAL", text) in log
        # PX4's own STATUSTEXT for it, beside the decoded event
        assert ("CRITICAL", "Failsafe activated") in log
