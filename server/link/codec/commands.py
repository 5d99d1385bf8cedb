"""What a request to a vehicle came to: its outcome, MAV_RESULT code, time and reason.

The protocol that produces these (tries, ACKs, confirmation) is in ``requests``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from pymavlink.dialects.v20 import development as mavlink

# How long past its end a request waits while frames wait unread on the link (a loop that
# fell behind may hold the answer): the command tries in all, a SETUP_SIGNING try each.
UNREAD_GRACE_S = 1.0


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


def not_sent(command_id: int, reason: str) -> CommandResult:
    """A command refused before sending, because something it needs is not known yet."""
    return CommandResult(command_name(command_id), command_id, CommandOutcome.FAILED, None, 0.0,
                         reason)  # fmt: skip
