"""The one request protocol (request, ACK, confirmation) against a fake vehicle, on virtual
loop time: retries, IN_PROGRESS, PX4's double ACK, confirmation by the reported state."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.commands import CommandOutcome
from server.link.codec.statustext import RecentTexts
from server.link.core.requests import Confirmation, Requester

pytestmark = pytest.mark.looptime

ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
SET_MODE = mavlink.MAV_CMD_DO_SET_MODE
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
IN_PROGRESS = mavlink.MAV_RESULT_IN_PROGRESS


class _FakeVehicle:
    """Records what is sent (with the loop time) and answers as the test scripts it."""

    def __init__(self) -> None:
        loop = asyncio.get_running_loop()
        self.sent: list[tuple[float, mavlink.MAVLink_message]] = []
        self.events: list[tuple[str, dict[str, object]]] = []
        self.on_send: Callable[[mavlink.MAVLink_message], None] = lambda _msg: None
        # answers waiting unread in the link's socket (a loop behind), and a flood of frames
        self.unread: list[mavlink.MAVLink_message] = []
        self.flooded = False
        self.requests = Requester(
            input_pending=self._input_pending,
            send=self._send,
            mav=mavlink.MAVLink(None, srcSystem=255, srcComponent=190),
            target=(1, 1),
            texts=RecentTexts(loop.time),
            publish=lambda kind, data: self.events.append((kind, data)),
        )

    def _input_pending(self) -> bool:
        """As the link's socket: what waits is read on the loop's next turn."""
        if self.unread:
            waiting, self.unread = self.unread, []
            for msg in waiting:
                asyncio.get_running_loop().call_soon(self.requests.handle_ack, msg, 1)
            return True
        return self.flooded

    def _send(self, msg: mavlink.MAVLink_message) -> None:
        self.sent.append((asyncio.get_running_loop().time(), msg))
        self.on_send(msg)

    def ack(self, command: int, result: int, *, after_s: float = 0.0, progress: int = 0) -> None:
        msg = mavlink.MAVLink_command_ack_message(command, result, progress, 0, 255, 190)
        asyncio.get_running_loop().call_later(after_s, self.requests.handle_ack, msg, 1)

    def later(self, after_s: float, change: Callable[[], None]) -> None:
        """A reported state that changes after_s from now."""

        def report() -> None:
            change()
            self.requests.changed()

        asyncio.get_running_loop().call_later(after_s, report)

    def accept_then(self, command: int, after_s: float, change: Callable[[], None]) -> None:
        """ACK every try ACCEPTED at once; the reported state changes after_s later."""

        def answer(_msg: mavlink.MAVLink_message) -> None:
            self.ack(command, ACCEPTED)
            self.later(after_s, change)

        self.on_send = answer


async def test_unanswered_command_is_sent_four_times_then_times_out() -> None:
    fake = _FakeVehicle()

    result = await fake.requests.command_long(ARM, 1)

    assert result.outcome is CommandOutcome.TIMEOUT
    assert [m.confirmation for _, m in fake.sent] == [0, 1, 2, 3]
    assert [t for t, _ in fake.sent] == pytest.approx([0.0, 0.5, 1.0, 1.5])
    assert result.elapsed_ms == pytest.approx(2000.0)


async def test_an_answer_unread_when_the_last_try_ends_is_read_not_timed_out() -> None:
    """The vehicle answered the last try, but the answer waits in the socket behind frames
    the loop has not read yet: it is read and counts; TIMEOUT would be untrue."""
    fake = _FakeVehicle()

    def answer_the_last(msg: mavlink.MAVLink_message) -> None:
        if msg.confirmation == 3:
            fake.unread.append(mavlink.MAVLink_command_ack_message(ARM, ACCEPTED, 0, 0, 255, 190))

    fake.on_send = answer_the_last

    result = await fake.requests.command_long(ARM, 1)

    assert result.ok
    assert len(fake.sent) == 4
    assert result.elapsed_ms == pytest.approx(2000.0, abs=10.0)


async def test_a_flood_of_unread_frames_delays_a_timeout_by_the_grace_at_most() -> None:
    fake = _FakeVehicle()
    fake.flooded = True  # frames always wait: the loop never catches up, nothing answers

    result = await fake.requests.command_long(ARM, 1)

    assert result.outcome is CommandOutcome.TIMEOUT
    assert len(fake.sent) == 4
    grace_ms = fake.requests.unread_grace_s * 1000
    assert 2000.0 + grace_ms <= result.elapsed_ms <= 2000.0 + grace_ms + 20.0


async def test_answer_to_the_second_try_ends_the_retries() -> None:
    fake = _FakeVehicle()
    fake.on_send = lambda m: fake.ack(ARM, ACCEPTED, after_s=0.1) if m.confirmation else None

    result = await fake.requests.command_long(ARM, 1)

    assert result.ok
    assert len(fake.sent) == 2
    assert result.elapsed_ms == pytest.approx(600.0)


async def test_in_progress_then_final_answer_waits_past_the_try_timeout_without_retries() -> None:
    fake = _FakeVehicle()

    def working(_msg: mavlink.MAVLink_message) -> None:
        fake.ack(ARM, IN_PROGRESS, progress=40)
        fake.ack(ARM, ACCEPTED, after_s=3.0)

    fake.on_send = working

    result = await fake.requests.command_long(ARM, 1)

    assert result.ok
    assert len(fake.sent) == 1
    assert result.elapsed_ms == pytest.approx(3000.0)
    progress = [d for k, d in fake.events if k == "command" and d["outcome"] == "IN_PROGRESS"]
    assert progress == [{"command": "MAV_CMD_COMPONENT_ARM_DISARM", "outcome": "IN_PROGRESS",
                         "progress": 40}]  # fmt: skip


async def test_in_progress_without_a_final_answer_times_out_after_the_progress_timeout() -> None:
    fake = _FakeVehicle()
    fake.requests.in_progress_timeout_s = 4.0
    fake.on_send = lambda _m: fake.ack(ARM, IN_PROGRESS, after_s=0.1)

    result = await fake.requests.command_long(ARM, 1)

    assert result.outcome is CommandOutcome.TIMEOUT
    assert len(fake.sent) == 1
    assert result.elapsed_ms == pytest.approx(4100.0)


@pytest.mark.parametrize(
    ("second_after_s", "outcome"),
    [(0.03, CommandOutcome.TEMPORARILY_REJECTED), (0.3, CommandOutcome.ACCEPTED)],
)
async def test_second_ack_of_set_mode_replaces_the_first_only_within_the_window(
    second_after_s: float, outcome: CommandOutcome
) -> None:
    fake = _FakeVehicle()

    def px4_double_ack(_msg: mavlink.MAVLink_message) -> None:
        fake.ack(SET_MODE, ACCEPTED)
        fake.ack(SET_MODE, TEMPORARILY_REJECTED, after_s=second_after_s)

    fake.on_send = px4_double_ack

    result = await fake.requests.command_long(SET_MODE, 1, 4, 3)

    assert result.outcome is outcome
    # the whole double-ACK window, then for a refusal 0.1 s for a STATUSTEXT saying why
    assert result.elapsed_ms == pytest.approx(200.0 if result.ok else 300.0)


async def test_other_commands_take_the_first_final_ack_at_once() -> None:
    fake = _FakeVehicle()
    fake.on_send = lambda _m: fake.ack(ARM, ACCEPTED, after_s=0.05)

    result = await fake.requests.command_long(ARM, 1)

    assert result.ok
    assert result.elapsed_ms == pytest.approx(50.0)


async def test_accepted_but_never_reported_is_not_confirmed_with_the_explanation() -> None:
    fake = _FakeVehicle()
    fake.on_send = lambda _m: fake.ack(SET_MODE, ACCEPTED)
    reported = {"mode": "HOLD"}
    confirm = Confirmation(
        reached=lambda: reported["mode"] == "LAND",
        timeout_s=3.0,
        explain=lambda s: f"still {reported['mode']} after {s:.1f} s",
    )

    result = await fake.requests.command_long(SET_MODE, 1, 4, 6, confirm=confirm, name="LAND")

    assert result.outcome is CommandOutcome.NOT_CONFIRMED
    assert result.reason == "still HOLD after 3.2 s"  # the ACK window, then 3 s of waiting
    assert result.command == "LAND"
    assert result.elapsed_ms == pytest.approx(3200.0)


async def test_confirmation_by_the_reported_state_resolves_when_it_shows() -> None:
    fake = _FakeVehicle()
    reported = {"mode": "HOLD"}
    fake.accept_then(SET_MODE, 0.7, lambda: reported.update(mode="LAND"))
    confirm = Confirmation(lambda: reported["mode"] == "LAND", 3.0, lambda _s: "never")

    result = await fake.requests.command_long(SET_MODE, 1, 4, 6, confirm=confirm)

    assert result.ok
    assert result.elapsed_ms == pytest.approx(700.0)


async def test_reported_state_that_shows_an_abort_fails_at_once() -> None:
    fake = _FakeVehicle()
    reported = {"vtol": "MC"}
    fake.accept_then(ARM, 0.4, lambda: reported.update(vtol="MC_AGAIN"))
    confirm = Confirmation(
        reached=lambda: reported["vtol"] == "FW",
        timeout_s=30.0,
        explain=lambda _s: f"vtol is {reported['vtol']}",
        aborted=lambda: reported["vtol"] == "MC_AGAIN",
    )

    result = await fake.requests.command_long(ARM, 1, confirm=confirm)

    assert result.outcome is CommandOutcome.FAILED
    assert result.reason == "vtol is MC_AGAIN"
    assert result.elapsed_ms == pytest.approx(400.0)


async def test_refused_command_is_not_waited_on_for_confirmation() -> None:
    fake = _FakeVehicle()
    fake.on_send = lambda _m: fake.ack(ARM, TEMPORARILY_REJECTED)
    confirm = Confirmation(lambda: False, 30.0, lambda _s: "never")

    result = await fake.requests.command_long(ARM, 1, confirm=confirm)

    assert result.outcome is CommandOutcome.TEMPORARILY_REJECTED
    assert result.elapsed_ms < 1000.0


async def test_message_without_ack_is_answered_by_the_reported_echo() -> None:
    fake = _FakeVehicle()
    echo: dict[str, int] = {}
    fake.on_send = lambda _m: fake.later(0.1, lambda: echo.update(seen=len(fake.sent)))

    def build() -> mavlink.MAVLink_message:
        return fake.requests.mav.set_gps_global_origin_encode(1, 470000000, 80000000, 500000, 0)

    # the first echo only answers the second try
    result = await fake.requests.message("SET_GPS_GLOBAL_ORIGIN", 48, build,
                                         lambda: echo.get("seen", 0) >= 2)  # fmt: skip

    assert result.ok
    assert len(fake.sent) == 2
    assert result.elapsed_ms == pytest.approx(600.0)


async def test_request_in_flight_ends_as_link_lost_when_the_vehicle_goes_silent() -> None:
    fake = _FakeVehicle()
    fake.on_send = lambda _m: asyncio.get_running_loop().call_later(
        0.2, fake.requests.fail_all
    )

    result = await fake.requests.command_long(ARM, 1)

    assert result.outcome is CommandOutcome.LINK_LOST
    assert result.elapsed_ms == pytest.approx(200.0)


async def test_a_cancelled_wait_ends_even_when_a_message_arrives_in_the_same_tick() -> None:
    # The vehicle calls changed() for every message, hundreds a second: a request cancelled
    # (the link closing) just as one arrives must still end, not run on through its retries.
    vehicle = _FakeVehicle()
    for _ in range(20):
        waiting = asyncio.create_task(vehicle.requests.wait_until(lambda: False, 5.0))
        await asyncio.sleep(0)
        vehicle.requests.changed()
        await asyncio.sleep(0)  # the event's waiter is done, the waiting task not yet woken
        waiting.cancel()
        with pytest.raises(asyncio.CancelledError):
            await asyncio.wait_for(waiting, 1.0)
