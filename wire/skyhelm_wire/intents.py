"""Intents: their requests (brake, velocity, offset, go-to) and their answer."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from skyhelm_wire.commands import CommandResultOut
from skyhelm_wire.common import LatDeg, LonDeg, StrictBody, YawDeg, limits_of
from skyhelm_wire.setpoint_kinds import AltitudeM, DegreesPerSecond, Metres, MetresPerSecond
from skyhelm_wire.setpoints import SentSetpointOut

SpeedMS = Annotated[float, limits_of(MetresPerSecond)]
DistanceM = Annotated[float, limits_of(Metres)]
IntentName = Literal["brake", "velocity", "offset", "goto"]
"""What a pilot or a script means (server.link.intents flies each)."""
YawRateDegS = Annotated[float | None, limits_of(DegreesPerSecond)]
AltRelM = Annotated[float | None, limits_of(AltitudeM)]


class BrakeBody(StrictBody):
    """No fields: stop and hold where the vehicle stops."""


class VelocityIntentBody(StrictBody):
    """Fly at a speed: (forward, right) in the body frame or (north, east)."""

    # the rules below, published: only the frame's own fields, and no climb with an
    # altitude hold
    model_config = ConfigDict(json_schema_extra={"allOf": [
        {
            "if": {"properties": {"frame": {"const": "ned"}}, "required": ["frame"]},
            "then": {"properties": {"forward_m_s": {"type": "null"},
                                    "right_m_s": {"type": "null"}}},
            "else": {"properties": {"north_m_s": {"type": "null"},
                                    "east_m_s": {"type": "null"}}},
        },
        {
            "if": {"properties": {"hold_altitude": {"const": True}},
                   "required": ["hold_altitude"]},
            "then": {"properties": {"up_m_s": {"const": 0}}},
        },
    ]})  # fmt: skip

    frame: Literal["body", "ned"] = "body"
    forward_m_s: SpeedMS | None = Field(None, description="frame body")
    right_m_s: SpeedMS | None = Field(None, description="frame body")
    north_m_s: SpeedMS | None = Field(None, description="frame ned")
    east_m_s: SpeedMS | None = Field(None, description="frame ned")
    up_m_s: SpeedMS = Field(0.0, description="positive up")
    yaw_rate_deg_s: YawRateDegS = Field(None, description="positive clockwise from above")
    hold_altitude: bool = Field(
        False, description="keep the altitude of the first such call instead of up_m_s"
    )
    live: bool = Field(
        True, description="hold-to-fly: braked and held when no update comes in time"
    )

    @model_validator(mode="after")
    def _fields_of_the_frame(self) -> VelocityIntentBody:
        other = ("north_m_s", "east_m_s") if self.frame == "body" else ("forward_m_s", "right_m_s")
        for name in other:
            if getattr(self, name) is not None:
                raise ValueError(f"{name} does not belong to frame {self.frame}")
        if self.hold_altitude and self.up_m_s != 0.0:
            raise ValueError("up_m_s must be 0 with hold_altitude")
        return self

    def xy_m_s(self) -> tuple[float, float]:
        """(forward, right) or (north, east), unset ones 0."""
        if self.frame == "body":
            return self.forward_m_s or 0.0, self.right_m_s or 0.0
        return self.north_m_s or 0.0, self.east_m_s or 0.0


class OffsetIntentBody(StrictBody):
    """Go by this many metres from where the vehicle is."""

    north_m: DistanceM = 0.0
    east_m: DistanceM = 0.0
    up_m: DistanceM = 0.0
    yaw_deg: YawDeg = None


class GotoIntentBody(StrictBody):
    """Go to a point, e.g. one clicked in the scene."""

    lat_deg: LatDeg
    lon_deg: LonDeg
    alt_rel_m: AltRelM = Field(None, description="above home; null: the current altitude")
    yaw_deg: YawDeg = None


class GeoTargetOut(BaseModel):
    lat_deg: float
    lon_deg: float
    alt_rel_m: float | None = Field(description="above home; null: unchanged")


class IntentOut(BaseModel):
    intent: IntentName
    via: Literal["setpoint", "reposition", "hold_mode"] = Field(
        description="an offboard setpoint, MAV_CMD_DO_REPOSITION, or HOLD mode"
    )
    setpoint: SentSetpointOut | None = Field(None, description="what is streamed, via setpoint")
    command: CommandResultOut | None = Field(None, description="the vehicle's answer, otherwise")
    target: GeoTargetOut | None = Field(None, description="where a move goes")
    live: bool = Field(False, description="watched by the deadman")
