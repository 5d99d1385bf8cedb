"""The MAVLink command protocol: COMMAND_LONG / COMMAND_INT out, COMMAND_ACK in.

Like MAVSDK and QGroundControl: 0.5 s per try, 3 retries with ``confirmation`` counting
up, IN_PROGRESS is not final. PX4 v1.16 answers DO_SET_MODE twice (ACCEPTED, then the
real answer), so for such commands a second ACK shortly after the first replaces it.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import math
from collections.abc import Callable, Collection
from dataclasses import dataclass

from pymavlink.dialects.v20 import development as mavlink

from server.link.statustext import RecentTexts

MAV_CMD_DO_SET_MODE = 176
MAV_RESULT_IN_PROGRESS = 5
NAN = math.nan


class CommandOutcome(enum.Enum):
    ACCEPTED = "ACCEPTED"
    TEMPORARILY_REJECTED = "TEMPORARILY_REJECTED"
    DENIED = "DENIED"
    UNSUPPORTED = "UNSUPPORTED"
    FAILED = "FAILED"
    IN_PROGRESS = "IN_PROGRESS"
    CANCELLED = "CANCELLED"
    TIMEOUT = "TIMEOUT"
    LINK_LOST = "LINK_LOST"
    NOT_CONFIRMED = "NOT_CONFIRMED"


# MAV_RESULT -> outcome; COMMAND_LONG_ONLY, COMMAND_INT_ONLY, UNSUPPORTED_MAV_FRAME count
# as UNSUPPORTED since the caller cannot do anything else about them.
_OUTCOME_BY_RESULT = {
    0: CommandOutcome.ACCEPTED,
    1: CommandOutcome.TEMPORARILY_REJECTED,
    2: CommandOutcome.DENIED,
    3: CommandOutcome.UNSUPPORTED,
    4: CommandOutcome.FAILED,
    5: CommandOutcome.IN_PROGRESS,
    6: CommandOutcome.CANCELLED,
    7: CommandOutcome.UNSUPPORTED,
    8: CommandOutcome.UNSUPPORTED,
    9: CommandOutcome.UNSUPPORTED,
}


def outcome_from_result(result: int) -> CommandOutcome:
    return _OUTCOME_BY_RESULT.get(result, CommandOutcome.FAILED)


def command_name(command_id: int) -> str:
    entry = mavlink.enums["MAV_CMD"].get(command_id)
    return entry.name if entry is not None else f"MAV_CMD_{command_id}"


@dataclass(frozen=True)
class CommandResult:
    command: str
    command_id: int
    outcome: CommandOutcome
    result_code: int | None
    elapsed_ms: float
    reason: str | None = None

    @property
    def ok(self) -> bool:
        return self.outcome is CommandOutcome.ACCEPTED


@dataclass(frozen=True)
class CommandInt:
    """COMMAND_INT payload: frame plus x/y as integers (degE7 for global frames)."""

    frame: int
    x: int
    y: int
    z: float


class _Pending:
    def __init__(self) -> None:
        self.changed = asyncio.Event()
        self.result: int | None = None
        self.first_final_s: float | None = None
        self.progress: int | None = None
        self.progress_acks = 0
        self.link_lost = False


class CommandProtocol:
    """Sends commands to one component and matches its ACKs by command id.

    One command per id is in flight at a time: a second call for the same id waits for
    the first to finish (an ACK carries only the command id, so two could not be told
    apart).
    """

    def __init__(
        self,
        *,
        send: Callable[[mavlink.MAVLink_message], None],
        mav: mavlink.MAVLink,
        target_system: int,
        target_component: int,
        own_system: int,
        texts: RecentTexts,
        publish: Callable[[str, dict[str, object]], None],
        timeout_s: float = 0.5,
        retries: int = 3,
        in_progress_timeout_s: float = 10.0,
        double_ack_window_s: float = 0.2,
        double_ack_commands: Collection[int] = (MAV_CMD_DO_SET_MODE,),
        reason_wait_s: float = 0.1,
    ) -> None:
        self._send = send
        self._mav = mav
        self._target = (target_system, target_component)
        self._own_system = own_system
        self._texts = texts
        self._publish = publish
        self.timeout_s = timeout_s
        self.retries = retries
        self.in_progress_timeout_s = in_progress_timeout_s
        self.double_ack_window_s = double_ack_window_s
        self.double_ack_commands = frozenset(double_ack_commands)
        self.reason_wait_s = reason_wait_s
        self._locks: dict[int, asyncio.Lock] = {}
        self._pending: dict[int, _Pending] = {}

    # -- incoming -----------------------------------------------------------------
    def handle_ack(self, msg: mavlink.MAVLink_command_ack_message, src_component: int) -> None:
        pending = self._pending.get(msg.command)
        if pending is None:
            return  # late (after timeout) or never asked: ignored
        if src_component != self._target[1] and self._target[1] != 0:
            return
        if msg.target_system not in (0, self._own_system):
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
        pending.changed.set()

    def fail_all(self) -> None:
        """The vehicle went silent: every command in flight ends as LINK_LOST."""
        for pending in self._pending.values():
            pending.link_lost = True
            pending.changed.set()

    # -- outgoing -----------------------------------------------------------------
    async def command_long(
        self, command: int, *params: float, timeout_s: float | None = None
    ) -> CommandResult:
        padded = [float(p) for p in params] + [NAN] * (7 - len(params))
        if len(padded) != 7:
            raise ValueError("COMMAND_LONG takes at most 7 params")

        def build(confirmation: int) -> mavlink.MAVLink_message:
            return self._mav.command_long_encode(*self._target, command, confirmation, *padded)

        return await self._run(command, build, timeout_s)

    async def command_int(
        self, command: int, where: CommandInt, *params: float, timeout_s: float | None = None
    ) -> CommandResult:
        padded = [float(p) for p in params] + [NAN] * (4 - len(params))
        if len(padded) != 4:
            raise ValueError("COMMAND_INT takes at most 4 float params")

        def build(_confirmation: int) -> mavlink.MAVLink_message:
            return self._mav.command_int_encode(
                *self._target, where.frame, command, 0, 0, *padded, where.x, where.y, where.z
            )

        return await self._run(command, build, timeout_s)

    async def _run(
        self, command: int, build: Callable[[int], mavlink.MAVLink_message], timeout_s: float | None
    ) -> CommandResult:
        lock = self._locks.setdefault(command, asyncio.Lock())
        async with lock:
            loop = asyncio.get_running_loop()
            started = loop.time()
            pending = _Pending()
            self._pending[command] = pending
            try:
                outcome = await self._exchange(pending, command, build, timeout_s)
            finally:
                del self._pending[command]
            reason = None
            if outcome not in (
                CommandOutcome.ACCEPTED,
                CommandOutcome.TIMEOUT,
                CommandOutcome.LINK_LOST,
            ):
                reason = await self._texts.wait_warning_since(
                    started - self.timeout_s, self.reason_wait_s
                )
            result = CommandResult(
                command=command_name(command),
                command_id=command,
                outcome=outcome,
                result_code=pending.result,
                elapsed_ms=(loop.time() - started) * 1000.0,
                reason=reason,
            )
            self._publish("command", {
                "command": result.command, "outcome": outcome.value,
                "result_code": result.result_code, "elapsed_ms": round(result.elapsed_ms, 1),
                "reason": reason,
            })  # fmt: skip
            return result

    async def _exchange(
        self,
        pending: _Pending,
        command: int,
        build: Callable[[int], mavlink.MAVLink_message],
        timeout_s: float | None,
    ) -> CommandOutcome:
        loop = asyncio.get_running_loop()
        per_try_s = self.timeout_s if timeout_s is None else timeout_s
        attempt = 0
        self._send(build(attempt))
        deadline = loop.time() + per_try_s
        seen_progress_acks = 0
        while pending.result is None:
            if pending.link_lost:
                return CommandOutcome.LINK_LOST
            if pending.progress_acks != seen_progress_acks:
                # every IN_PROGRESS says the vehicle is still working: wait longer, no retry
                seen_progress_acks = pending.progress_acks
                deadline = loop.time() + self.in_progress_timeout_s
                self._publish(
                    "command",
                    {
                        "command": command_name(command),
                        "outcome": "IN_PROGRESS",
                        "progress": pending.progress,
                    },
                )
            if loop.time() >= deadline:
                if seen_progress_acks or attempt >= self.retries:
                    return CommandOutcome.TIMEOUT
                attempt += 1
                self._send(build(attempt))
                deadline = loop.time() + per_try_s
            pending.changed.clear()
            await _wait_event(pending.changed, deadline - loop.time())
        if command in self.double_ack_commands:
            assert pending.first_final_s is not None
            window_end = pending.first_final_s + self.double_ack_window_s
            while loop.time() < window_end and not pending.link_lost:
                pending.changed.clear()
                await _wait_event(pending.changed, window_end - loop.time())
        return outcome_from_result(pending.result)


async def _wait_event(event: asyncio.Event, timeout_s: float) -> None:
    if timeout_s <= 0:
        return
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(event.wait(), timeout_s)
