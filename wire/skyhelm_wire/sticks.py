"""Manual control: the sticks a pilot or a script flies with (MANUAL_CONTROL at 25 Hz)."""

from __future__ import annotations

from pydantic import BaseModel, Field

from skyhelm_wire.common import StrictBody
from skyhelm_wire.state import StreamOut


class SticksBody(StrictBody):
    """Stick positions. Centred sticks (0, 0, 0, throttle 0.5) hold position and altitude
    in POSCTL, altitude in ALTCTL, and give hover thrust in STABILIZED."""

    pitch: float = Field(0.0, ge=-1.0, le=1.0, description="forward +, back -")
    roll: float = Field(0.0, ge=-1.0, le=1.0, description="right +, left -")
    yaw: float = Field(0.0, ge=-1.0, le=1.0, description="clockwise +")
    throttle: float = Field(
        0.5, ge=0.0, le=1.0, description="0 down, 0.5 centred (hold altitude / hover), 1 up"
    )


class SticksOut(BaseModel):
    active: bool = Field(description="MANUAL_CONTROL is being sent")
    sticks: SticksBody | None = Field(description="what is sent now")
    rate_hz: float = Field(description="the send rate (QGroundControl's 25 Hz)")
    stream: StreamOut = Field(description="figures of the MANUAL_CONTROL stream")
