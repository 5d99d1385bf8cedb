"""Commands: their request bodies (arm, takeoff, modes, reposition, home, offboard) and
what a command comes to, the vehicle's COMMAND_ACK result (or why there was none)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from skyhelm_wire.common import AltM, LatDeg, LonDeg, StrictBody, YawDeg
from skyhelm_wire.modes import ModeName
from skyhelm_wire.setpoints import SetpointBody

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


# -- request bodies ---------------------------------------------------------------------


class ArmBody(StrictBody):
    force: bool = False


class TakeoffBody(StrictBody):
    altitude_m: Annotated[float | None, Field(gt=0.0, le=1.0e4)] = Field(
        None, description="above home; None = the vehicle's MIS_TAKEOFF_ALT"
    )


class ModeBody(StrictBody):
    mode: ModeName


class RepositionBody(StrictBody):
    # the rule below, published: never both altitudes as numbers
    model_config = ConfigDict(json_schema_extra={"not": {
        "required": ["alt_amsl_m", "alt_rel_m"],
        "properties": {"alt_amsl_m": {"type": "number"}, "alt_rel_m": {"type": "number"}},
    }})  # fmt: skip

    lat_deg: LatDeg
    lon_deg: LonDeg
    alt_amsl_m: AltM | None = None
    alt_rel_m: AltM | None = None
    ground_speed_m_s: Annotated[float | None, Field(gt=0.0, le=1.0e3)] = None
    yaw_deg: YawDeg = None
    loiter_radius_m: Annotated[float | None, Field(gt=0.0, le=1.0e5)] = None

    @model_validator(mode="after")
    def _one_altitude(self) -> RepositionBody:
        if self.alt_amsl_m is not None and self.alt_rel_m is not None:
            raise ValueError("give alt_amsl_m or alt_rel_m, not both")
        return self


class VtolTransitionBody(StrictBody):
    to: Literal["fixed_wing", "multicopter"]
    immediate: bool = Field(False, description="switch at once, without a transition phase")
    wait: bool = Field(True, description="answer once the vehicle reports the new VTOL state")


class OriginBody(StrictBody):
    lat_deg: LatDeg
    lon_deg: LonDeg
    alt_amsl_m: AltM


class HomeBody(StrictBody):
    """All three fields, or none for the current position."""

    # the rule below, published: a number for lat_deg asks one for lon_deg, and the reverse
    model_config = ConfigDict(json_schema_extra={"allOf": [
        {"if": {"required": [a], "properties": {a: {"type": "number"}}},
         "then": {"required": [b], "properties": {b: {"type": "number"}}}}
        for a, b in (("lat_deg", "lon_deg"), ("lon_deg", "lat_deg"))
    ]})  # fmt: skip

    lat_deg: LatDeg | None = None
    lon_deg: LonDeg | None = None
    alt_amsl_m: AltM | None = None

    @model_validator(mode="after")
    def _lat_lon_together(self) -> HomeBody:
        if (self.lat_deg is None) != (self.lon_deg is None):
            raise ValueError("give lat_deg and lon_deg together, or neither")
        return self


class OffboardStartBody(StrictBody):
    setpoint: SetpointBody | None = None


class OffboardStopBody(StrictBody):
    then_mode: ModeName = "HOLD"
