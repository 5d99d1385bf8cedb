"""Asking a vehicle for something: request, answer, confirmation, in one place.

Every request of every vehicle plugin goes through ``Requester``:

- a command (COMMAND_LONG / COMMAND_INT) is answered by COMMAND_ACK. Like MAVSDK and
  QGroundControl: 0.5 s per try, 3 retries with ``confirmation`` counting up; IN_PROGRESS
  is not final (it stops the retries and extends the wait). PX4 v1.16 answers DO_SET_MODE
  twice (ACCEPTED, then the real answer), so for such commands a second ACK shortly after
  the first replaces it.
- a message without an ACK (SET_GPS_GLOBAL_ORIGIN, PARAM_REQUEST_READ, PARAM_SET) is
  answered by what the vehicle reports back: the same tries, until a predicate holds.
- an accepted command may also have to show in the reported state (a mode, a VTOL state):
  a ``Confirmation`` says how. Accepted but never shown is NOT_CONFIRMED.

No try ends while frames wait unread on the link (``input_pending``): a loop that fell
behind (a busy machine, a backlog read 64 frames a turn) reads them first, as the link's
liveness verdicts do, so TIMEOUT means the vehicle did not answer, not that its answer was
still queued. The wait for them is bounded (``unread_grace_s``): a flood cannot hide a
vehicle that never answers.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.commands import (
    UNREAD_GRACE_S,
    CommandInt,
    CommandOutcome,
    CommandResult,
    command_name,
    outcome_from_result,
)
from server.link.codec.statustext import RecentTexts

MAV_CMD_DO_SET_MODE = 176
MAV_RESULT_IN_PROGRESS = 5
NAN = math.nan
# how often a try past its end looks again while the link reads the frames waiting
UNREAD_POLL_S = 0.005
# outcomes that a STATUSTEXT may explain (PX4 says why it refused)
_EXPLAINED = frozenset(set(CommandOutcome) - {
    CommandOutcome.ACCEPTED, CommandOutcome.TIMEOUT, CommandOutcome.LINK_LOST,
    CommandOutcome.NOT_CONFIRMED,
})  # fmt: skip

Publish = Callable[[str, dict[str, object]], None]
# given when the command started and the STATUSTEXT reason found (if any), a better reason
# (PX4's decoded EVENT that follows its COMMAND_ACK) or the one given
Explainer = Callable[[float, str | None], Awaitable[str | None]]


def _never() -> bool:
    return False


@dataclass(frozen=True)
class Confirmation:
    """How the reported state shows that an accepted command took effect."""

    reached: Callable[[], bool]
    timeout_s: float
    explain: Callable[[float], str]  # why not, given the seconds since the request
    aborted: Callable[[], bool] = _never  # the vehicle gave up: no waiting on
    aborted_outcome: CommandOutcome = CommandOutcome.FAILED


class _Pending:
    """One request in flight and what has come back for it."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.result: int | None = None
        self.first_final_s: float | None = None
        self.progress: int | None = None
        self.progress_acks = 0
        self.link_lost = False


class Requester:
    """Sends requests to one component and waits for their answers.

    One command per id is in flight at a time: a second call for the same id waits for the
    first to finish (an ACK carries only the command id, so two could not be told apart).
    Waiting is on ``changed()``, which the vehicle calls after every message it took in.
    """

    timeout_s = 0.5  # per try
    retries = 3
    in_progress_timeout_s = 10.0  # after each IN_PROGRESS
    double_ack_window_s = 0.2
    double_ack_commands = frozenset({MAV_CMD_DO_SET_MODE})
    reason_wait_s = 0.1  # for the STATUSTEXT that says why a command was refused
    unread_grace_s = UNREAD_GRACE_S  # past the tries' ends in all, while frames wait unread

    def __init__(
        self,
        *,
        send: Callable[[mavlink.MAVLink_message], None],
        mav: mavlink.MAVLink,
        target: tuple[int, int],
        texts: RecentTexts,
        publish: Publish,
        input_pending: Callable[[], bool] = _never,
    ) -> None:
        self.send = send
        self._input_pending = input_pending
        self.mav = mav
        self.target = target  # (system, component)
        self._texts = texts
        self._publish = publish
        self._changed = asyncio.Event()
        self._locks: dict[int, asyncio.Lock] = {}
        self._awaiting_ack: dict[int, _Pending] = {}
        self._in_flight: set[_Pending] = set()
        self.explainers: list[Explainer] = []

    # -- incoming -----------------------------------------------------------------
    def changed(self) -> None:
        """Something arrived: every waiter looks again."""
        self._changed.set()

    def handle_ack(self, msg: mavlink.MAVLink_command_ack_message, src_component: int) -> None:
        pending = self._awaiting_ack.get(msg.command)
        if pending is None:
            return  # late (after timeout) or never asked: ignored
        if src_component != self.target[1] and self.target[1] != 0:
            return
        if msg.target_system not in (0, self.mav.srcSystem):
            return  # answer to another ground station
        now = asyncio.get_running_loop().time()
        if msg.result == MAV_RESULT_IN_PROGRESS:
            if pending.result is None:
                pending.progress = msg.progress
                pending.progress_acks += 1
        elif pending.first_final_s is None:
            pending.result = msg.result
            pending.first_final_s = now
        elif now - pending.first_final_s <= self.double_ack_window_s:
            pending.result = msg.result
        self.changed()

    def fail_all(self) -> None:
        """The vehicle went silent: every request in flight ends as LINK_LOST."""
        for pending in self._in_flight:
            pending.link_lost = True
        self.changed()

    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Wait until ``predicate()`` holds after some message; False on timeout."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while not predicate():
            remaining = deadline - loop.time()
            if remaining <= 0:
                return False
            self._changed.clear()
            # asyncio.timeout, not wait_for: on Python 3.11 wait_for loses a cancellation
            # that arrives as the event is set, and a closing link then waits for every
            # request still queued behind this one
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(remaining):
                    await self._changed.wait()
        return True

    # -- outgoing -----------------------------------------------------------------
    async def command_long(
        self,
        command: int,
        *params: float,
        timeout_s: float | None = None,
        confirm: Confirmation | None = None,
        name: str | None = None,
    ) -> CommandResult:
        padded = [float(p) for p in params] + [NAN] * (7 - len(params))
        if len(padded) != 7:
            raise ValueError("COMMAND_LONG takes at most 7 params")

        def build(confirmation: int) -> mavlink.MAVLink_message:
            return self.mav.command_long_encode(*self.target, command, confirmation, *padded)

        return await self.command(command, build, timeout_s=timeout_s, confirm=confirm,
                                  name=name)  # fmt: skip

    async def command_int(
        self, command: int, where: CommandInt, *params: float, timeout_s: float | None = None
    ) -> CommandResult:
        padded = [float(p) for p in params] + [NAN] * (4 - len(params))
        if len(padded) != 4:
            raise ValueError("COMMAND_INT takes at most 4 float params")

        def build(_confirmation: int) -> mavlink.MAVLink_message:
            return self.mav.command_int_encode(
                *self.target, where.frame, command, 0, 0, *padded, where.x, where.y, where.z
            )

        return await self.command(command, build, timeout_s=timeout_s)

    async def command(
        self,
        command: int,
        build: Callable[[int], mavlink.MAVLink_message],
        *,
        timeout_s: float | None = None,
        confirm: Confirmation | None = None,
        name: str | None = None,
    ) -> CommandResult:
        """Send ``build(try number)`` until the vehicle ACKs it, then (if asked) wait for
        the reported state to confirm it."""
        loop = asyncio.get_running_loop()
        started = loop.time()
        pending = _Pending(name or command_name(command))
        async with self._locks.setdefault(command, asyncio.Lock()):
            self._awaiting_ack[command] = pending
            try:
                outcome = await self._acked(pending, command, build, timeout_s)
            finally:
                del self._awaiting_ack[command]
        reason = None
        if outcome is CommandOutcome.ACCEPTED and confirm is not None:
            outcome, reason = await self._confirmed(confirm, started)
        elif outcome in _EXPLAINED:
            reason = await self._texts.wait_warning_since(
                started - self.timeout_s, self.reason_wait_s
            )
            for explain in self.explainers:
                reason = await explain(started, reason)
        return self._finish(pending, command, outcome, started, reason)

    async def message(
        self,
        name: str,
        msg_id: int,
        build: Callable[[], mavlink.MAVLink_message],
        answered: Callable[[], bool],
        *,
        timeout_s: float | None = None,
    ) -> CommandResult:
        """A message the vehicle answers by reporting something back: ACCEPTED once
        ``answered()`` holds, TIMEOUT when it never does."""
        started = asyncio.get_running_loop().time()
        pending = _Pending(name)
        outcome = await self._tries(pending, lambda _: self.send(build()), answered, timeout_s)
        return self._finish(pending, msg_id, outcome, started, None)

    async def until(
        self,
        request: Callable[[], None],
        answered: Callable[[], bool],
        timeout_s: float | None = None,
    ) -> bool:
        """Call ``request`` up to 1 + retries times until ``answered()`` holds."""
        outcome = await self._tries(_Pending(""), lambda _: request(), answered, timeout_s)
        return outcome is CommandOutcome.ACCEPTED

    # -- the one retry loop -------------------------------------------------------------
    async def _tries(
        self,
        pending: _Pending,
        send_try: Callable[[int], None],
        answered: Callable[[], bool],
        timeout_s: float | None,
    ) -> CommandOutcome:
        """ACCEPTED once answered, else TIMEOUT or LINK_LOST. Every IN_PROGRESS ACK says
        the vehicle is still working: it extends the wait and ends the retries."""
        loop = asyncio.get_running_loop()
        per_try_s = self.timeout_s if timeout_s is None else timeout_s
        self._in_flight.add(pending)
        try:
            attempt = seen_progress = 0
            grace_left_s = self.unread_grace_s
            send_try(attempt)
            deadline = loop.time() + per_try_s
            while not answered():
                if pending.link_lost:
                    return CommandOutcome.LINK_LOST
                if pending.progress_acks != seen_progress:
                    seen_progress = pending.progress_acks
                    deadline = loop.time() + self.in_progress_timeout_s
                    self._publish("command", {"command": pending.name, "outcome": "IN_PROGRESS",
                                              "progress": pending.progress})  # fmt: skip
                if loop.time() >= deadline:
                    if self._input_pending() and loop.time() < deadline + grace_left_s:
                        await asyncio.sleep(UNREAD_POLL_S)  # the link reads what waits
                        continue
                    grace_left_s = max(0.0, grace_left_s - (loop.time() - deadline))
                    if seen_progress or attempt >= self.retries:
                        return CommandOutcome.TIMEOUT
                    attempt += 1
                    send_try(attempt)
                    deadline = loop.time() + per_try_s

                def moved(seen: int = seen_progress) -> bool:
                    return answered() or pending.link_lost or pending.progress_acks != seen

                await self.wait_until(moved, deadline - loop.time())
            return CommandOutcome.ACCEPTED
        finally:
            self._in_flight.discard(pending)

    async def _acked(
        self,
        pending: _Pending,
        command: int,
        build: Callable[[int], mavlink.MAVLink_message],
        timeout_s: float | None,
    ) -> CommandOutcome:
        def send_try(attempt: int) -> None:
            self.send(build(attempt))

        outcome = await self._tries(
            pending, send_try, lambda: pending.result is not None, timeout_s
        )
        if outcome is not CommandOutcome.ACCEPTED or pending.result is None:
            return outcome
        if command in self.double_ack_commands and pending.first_final_s is not None:
            window_end_s = pending.first_final_s + self.double_ack_window_s
            loop = asyncio.get_running_loop()
            self._in_flight.add(pending)
            try:
                await self.wait_until(lambda: pending.link_lost, window_end_s - loop.time())
            finally:
                self._in_flight.discard(pending)
        return outcome_from_result(pending.result)

    async def _confirmed(
        self, confirm: Confirmation, started: float
    ) -> tuple[CommandOutcome, str | None]:
        await self.wait_until(lambda: confirm.reached() or confirm.aborted(), confirm.timeout_s)
        if confirm.reached():
            return CommandOutcome.ACCEPTED, None
        elapsed_s = asyncio.get_running_loop().time() - started
        outcome = confirm.aborted_outcome if confirm.aborted() else CommandOutcome.NOT_CONFIRMED
        return outcome, confirm.explain(elapsed_s)

    def _finish(
        self,
        pending: _Pending,
        command_id: int,
        outcome: CommandOutcome,
        started: float,
        reason: str | None,
    ) -> CommandResult:
        result = CommandResult(
            command=pending.name,
            command_id=command_id,
            outcome=outcome,
            result_code=pending.result,
            elapsed_ms=(asyncio.get_running_loop().time() - started) * 1000.0,
            reason=reason,
        )
        self._publish("command", {
            "command": result.command, "outcome": outcome.value,
            "result_code": result.result_code, "elapsed_ms": round(result.elapsed_ms, 1),
            "reason": reason,
        })  # fmt: skip
        return result
