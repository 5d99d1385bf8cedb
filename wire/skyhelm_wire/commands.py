"""What a command comes to: the vehicle's COMMAND_ACK result (or why there was none)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field

CommandResultName = Literal[
    "ACCEPTED",
    "TEMPORARILY_REJECTED",
    "DENIED",
    "UNSUPPORTED",
    "FAILED",
    "IN_PROGRESS",
    "CANCELLED",
    "TIMEOUT",
    "LINK_LOST",
    "NOT_CONFIRMED",
]


class CommandResultOut(BaseModel):
    command: str = Field(examples=["MAV_CMD_COMPONENT_ARM_DISARM"])
    result: CommandResultName
    result_code: int | None = Field(description="MAV_RESULT as received")
    elapsed_ms: float
    reason: str | None = Field(None, description="the vehicle's STATUSTEXT explaining a refusal")
