"""PX4's flight modes by name: what the API's mode bodies take and the state reports. The
link's codec (server/link/codec/modes.py) holds each name's PX4 numbers;
tests/link/test_modes.py holds the two to the same names."""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator, Field

PX4_MODE_NAMES: tuple[str, ...] = (
    "MANUAL", "ALTCTL", "POSCTL", "POSCTL_ORBIT", "ACRO", "STABILIZED", "OFFBOARD", "HOLD",
    "TAKEOFF", "LAND", "RTL", "MISSION", "FOLLOW_TARGET", "PRECLAND", "VTOL_TAKEOFF",
    "TERMINATION", "RATTITUDE", "READY",
)  # fmt: skip
"""Every mode name, in PX4's order."""


def _known_mode(mode: str) -> str:
    if mode not in PX4_MODE_NAMES:
        raise ValueError(f"unknown mode {mode!r}; PX4 modes are {', '.join(PX4_MODE_NAMES)}")
    return mode


ModeName = Annotated[
    str,
    Field(json_schema_extra={"enum": list(PX4_MODE_NAMES)}, examples=["OFFBOARD", "HOLD"]),
    AfterValidator(_known_mode),
]
