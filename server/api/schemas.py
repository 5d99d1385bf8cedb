"""Request and response models of the v1 API. Field names carry units; enum values are the
PX4/MAVLink names the link layer uses."""

from __future__ import annotations

from dataclasses import asdict
from typing import Annotated, Any, ClassVar, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, model_validator

from server.link import (
    PX4_MODE_NAMES,
    Attitude,
    BodyRates,
    OffsetBody,
    OffsetNed,
    PositionGlobal,
    PositionNed,
    PositionVelocityNed,
    RawLocal,
    Setpoint,
    VelocityBody,
    VelocityNed,
)
from server.link import AccelerationNed as _AccelerationNed

# Bounds keep every number packable into MAVLink's float32/int fields: a value the wire
# cannot carry is a 422, never a crash while encoding.
Metres = Annotated[float, Field(ge=-1.0e6, le=1.0e6)]
Speed = Annotated[float, Field(ge=-1.0e3, le=1.0e3)]
Accel = Annotated[float, Field(ge=-1.0e3, le=1.0e3)]
YawDeg = Annotated[float | None, Field(ge=-360.0, le=360.0)]
AngleDeg = Annotated[float, Field(ge=-360.0, le=360.0)]
RateDegS = Annotated[float, Field(ge=-3600.0, le=3600.0)]
Thrust = Annotated[float, Field(ge=0.0, le=1.0)]
LatDeg = Annotated[float, Field(ge=-90.0, le=90.0)]
LonDeg = Annotated[float, Field(ge=-180.0, le=180.0)]
AltM = Annotated[float, Field(ge=-1.0e3, le=1.0e5)]


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class _SetpointBody(_Body):
    link_type: ClassVar[type[Any]]

    def to_link(self) -> Setpoint:
        fields = self.model_dump(exclude={"type"})
        setpoint: Setpoint = self.link_type(**fields)
        return setpoint


class PositionNedBody(_SetpointBody):
    link_type = PositionNed
    type: Literal["position_ned"]
    north_m: Metres
    east_m: Metres
    down_m: Metres
    yaw_deg: YawDeg = None


class VelocityNedBody(_SetpointBody):
    link_type = VelocityNed
    type: Literal["velocity_ned"]
    north_m_s: Speed
    east_m_s: Speed
    down_m_s: Speed
    yaw_deg: YawDeg = None
    yaw_rate_deg_s: Annotated[float | None, Field(ge=-3600.0, le=3600.0)] = None


class VelocityBodyBody(_SetpointBody):
    link_type = VelocityBody
    type: Literal["velocity_body"]
    forward_m_s: Speed
    right_m_s: Speed
    down_m_s: Speed
    yaw_rate_deg_s: Annotated[float | None, Field(ge=-3600.0, le=3600.0)] = None


class AccelerationNedBody(_SetpointBody):
    link_type = _AccelerationNed
    type: Literal["acceleration_ned"]
    north_m_s2: Accel
    east_m_s2: Accel
    down_m_s2: Accel
    yaw_deg: YawDeg = None


class PositionVelocityNedBody(_SetpointBody):
    link_type = PositionVelocityNed
    type: Literal["position_velocity_ned"]
    north_m: Metres
    east_m: Metres
    down_m: Metres
    north_m_s: Speed
    east_m_s: Speed
    down_m_s: Speed
    north_m_s2: Annotated[float | None, Field(ge=-1.0e3, le=1.0e3)] = None
    east_m_s2: Annotated[float | None, Field(ge=-1.0e3, le=1.0e3)] = None
    down_m_s2: Annotated[float | None, Field(ge=-1.0e3, le=1.0e3)] = None
    yaw_deg: YawDeg = None


class PositionGlobalBody(_SetpointBody):
    link_type = PositionGlobal
    type: Literal["position_global"]
    lat_deg: LatDeg
    lon_deg: LonDeg
    alt_m: AltM
    alt_frame: Literal["amsl", "relative", "terrain"] = "amsl"
    yaw_deg: YawDeg = None


class AttitudeBody(_SetpointBody):
    link_type = Attitude
    type: Literal["attitude"]
    roll_deg: AngleDeg
    pitch_deg: AngleDeg
    yaw_deg: AngleDeg
    thrust: Thrust


class BodyRatesBody(_SetpointBody):
    link_type = BodyRates
    type: Literal["body_rates"]
    roll_rate_deg_s: RateDegS
    pitch_rate_deg_s: RateDegS
    yaw_rate_deg_s: RateDegS
    thrust: Thrust


class OffsetNedBody(_SetpointBody):
    link_type = OffsetNed
    type: Literal["offset_ned"]
    north_m: Metres
    east_m: Metres
    down_m: Metres
    yaw_deg: YawDeg = None


class OffsetBodyBody(_SetpointBody):
    link_type = OffsetBody
    type: Literal["offset_body"]
    forward_m: Metres
    right_m: Metres
    down_m: Metres
    yaw_deg: YawDeg = None


class RawLocalBody(_SetpointBody):
    """SET_POSITION_TARGET_LOCAL_NED as PX4 reads it: MAV_FRAME number, POSITION_TARGET_TYPEMASK
    bits, SI units (yaw in rad, yaw_rate in rad/s)."""

    link_type = RawLocal
    type: Literal["raw_local"]
    frame: int = Field(ge=0, le=255)
    type_mask: int = Field(ge=0, le=65535)
    x: Metres = 0.0
    y: Metres = 0.0
    z: Metres = 0.0
    vx: Speed = 0.0
    vy: Speed = 0.0
    vz: Speed = 0.0
    afx: Accel = 0.0
    afy: Accel = 0.0
    afz: Accel = 0.0
    yaw: Annotated[float, Field(ge=-10.0, le=10.0)] = 0.0
    yaw_rate: Annotated[float, Field(ge=-100.0, le=100.0)] = 0.0


SetpointBody = Annotated[
    PositionNedBody
    | VelocityNedBody
    | VelocityBodyBody
    | AccelerationNedBody
    | PositionVelocityNedBody
    | PositionGlobalBody
    | AttitudeBody
    | BodyRatesBody
    | OffsetNedBody
    | OffsetBodyBody
    | RawLocalBody,
    Field(discriminator="type"),
]

_BODY_BY_LINK_TYPE: dict[type[Any], type[_SetpointBody]] = {
    body.link_type: body
    for body in (
        PositionNedBody,
        VelocityNedBody,
        VelocityBodyBody,
        AccelerationNedBody,
        PositionVelocityNedBody,
        PositionGlobalBody,
        AttitudeBody,
        BodyRatesBody,
        OffsetNedBody,
        OffsetBodyBody,
        RawLocalBody,
    )
}


def setpoint_as_dict(setpoint: Setpoint) -> dict[str, Any]:
    """The wire form of a link setpoint: its fields plus the `type` the API names it by."""
    body = _BODY_BY_LINK_TYPE[type(setpoint)]
    type_name = body.model_fields["type"].annotation.__args__[0]  # type: ignore[union-attr]
    return {"type": type_name, **asdict(setpoint)}


# ---- commands ---------------------------------------------------------------------------


class ArmBody(_Body):
    force: bool = False


class TakeoffBody(_Body):
    altitude_m: Annotated[float | None, Field(gt=0.0, le=1.0e4)] = Field(
        None, description="above home; None = the vehicle's MIS_TAKEOFF_ALT"
    )


def _known_mode(mode: str) -> str:
    if mode not in PX4_MODE_NAMES:
        raise ValueError(f"unknown mode {mode!r}; PX4 modes are {', '.join(PX4_MODE_NAMES)}")
    return mode


ModeName = Annotated[
    str,
    Field(json_schema_extra={"enum": list(PX4_MODE_NAMES)}, examples=["OFFBOARD", "HOLD"]),
    AfterValidator(_known_mode),
]


class ModeBody(_Body):
    mode: ModeName


class RepositionBody(_Body):
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


class VtolTransitionBody(_Body):
    to: Literal["fixed_wing", "multicopter"]
    immediate: bool = False
    wait: bool = True


class OriginBody(_Body):
    lat_deg: LatDeg
    lon_deg: LonDeg
    alt_amsl_m: AltM


class HomeBody(_Body):
    """All three fields, or none for the current position."""

    lat_deg: LatDeg | None = None
    lon_deg: LonDeg | None = None
    alt_amsl_m: AltM | None = None

    @model_validator(mode="after")
    def _lat_lon_together(self) -> HomeBody:
        if (self.lat_deg is None) != (self.lon_deg is None):
            raise ValueError("give lat_deg and lon_deg together, or neither")
        return self


class OffboardStartBody(_Body):
    setpoint: SetpointBody | None = None


class OffboardStopBody(_Body):
    then_mode: ModeName = "HOLD"


class ControlBody(_Body):
    takeover: bool = False
    client_name: Annotated[str | None, Field(max_length=64, description="shown to others")] = None


class ParamValueBody(_Body):
    value: Annotated[float, Field(ge=-3.4e38, le=3.4e38)] | int = Field(
        description="an integer for INT32 parameters, a number for REAL32"
    )


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


class SentSetpointOut(BaseModel):
    setpoint: dict[str, Any] = Field(description="as sent: the request's shape, offsets resolved")
    message: str = Field(examples=["SET_POSITION_TARGET_LOCAL_NED"])
    frame: int
    type_mask: int


class LeaseOut(BaseModel):
    lease_id: str
    ttl_s: float
    holder: str
    expires_in_s: float


class LeaseStatusOut(BaseModel):
    holder: str | None
    expires_in_s: float | None


class ErrorDetail(BaseModel):
    reason: str
    field: str | None = None
    limit: float | None = None
    holder: str | None = None


class ErrorOut(BaseModel):
    detail: ErrorDetail


class HealthOut(BaseModel):
    status: Literal["ok"]
    version: str
    vehicles: int
    read_only: bool = Field(False, description="a replayed recording: control calls answer 403")


class ParamsOut(BaseModel):
    params: dict[str, float | int | None]


class ParamOut(BaseModel):
    name: str
    value: float | int | None


# ---- state ------------------------------------------------------------------------------


class _Out(BaseModel):
    model_config = ConfigDict(extra="ignore")


class PositionNedOut(_Out):
    north_m: float | None
    east_m: float | None
    down_m: float | None


class VelocityNedOut(_Out):
    north_m_s: float | None
    east_m_s: float | None
    down_m_s: float | None


class GlobalOut(_Out):
    lat_deg: float | None
    lon_deg: float | None
    alt_amsl_m: float | None
    alt_rel_m: float | None


class AttitudeOut(_Out):
    roll_deg: float | None
    pitch_deg: float | None
    yaw_deg: float | None
    rollspeed_deg_s: float | None = None
    pitchspeed_deg_s: float | None = None
    yawspeed_deg_s: float | None = None


class BatteryOut(_Out):
    voltage_v: float | None
    current_a: float | None
    remaining_pct: float | None


class GpsOut(_Out):
    fix_type: str
    satellites: int
    hdop: float | None


class HomeOut(_Out):
    lat_deg: float | None
    lon_deg: float | None
    alt_amsl_m: float | None
    north_m: float | None
    east_m: float | None
    down_m: float | None


class OriginOut(_Out):
    lat_deg: float | None
    lon_deg: float | None
    alt_amsl_m: float | None


class StreamOut(_Out):
    active: bool
    rate_hz: float | None
    interval_p50_ms: float | None = None
    interval_p99_ms: float | None
    max_gap_ms: float | None
    gaps: int = 0
    sent: int
    since_last_ms: float | None = None


class LinkOut(_Out):
    url: str
    connected: bool
    frames_in: int
    frames_out: int
    bytes_in: int
    bytes_out: int
    lost_frames: int
    bad_frames: int
    last_heartbeat_age_s: float | None
    reconnects: int = 0


class StatusTextOut(_Out):
    time_s: float
    severity: str
    text: str


class VehicleSummaryOut(_Out):
    id: int
    sysid: int
    type: str = Field(examples=["QUADROTOR"])
    autopilot: str
    connected: bool
    mode: str
    armed: bool
    link: LinkOut


class VehicleStateOut(_Out):
    model_config = ConfigDict(extra="ignore", populate_by_name=True)

    id: int
    sysid: int
    compid: int
    type: str
    autopilot: str
    connected: bool
    last_heartbeat_age_s: float | None
    mode: str
    user_mode: str | None
    armed: bool
    system_status: str
    landed_state: Literal["UNDEFINED", "ON_GROUND", "IN_AIR", "TAKEOFF", "LANDING"]
    vtol_state: Literal["UNDEFINED", "MC", "FW", "TRANSITION_TO_FW", "TRANSITION_TO_MC"]
    position_ned: PositionNedOut | None
    velocity_ned: VelocityNedOut | None
    global_: GlobalOut | None = Field(alias="global")
    attitude: AttitudeOut | None
    ground_speed_m_s: float | None
    air_speed_m_s: float | None
    climb_rate_m_s: float | None
    heading_deg: float | None
    battery: BatteryOut | None
    gps: GpsOut | None
    home: HomeOut | None
    origin: OriginOut | None
    setpoint: dict[str, Any] | None
    target_ned: PositionNedOut | None
    stream: StreamOut
    lease: LeaseStatusOut
    actuator_outputs: list[float | None]
    statustext: list[StatusTextOut]
    rtl_phase: str | None
    link: LinkOut
    updated_s: float = Field(description="time.monotonic() of the newest telemetry")


class UnprocessableOut(BaseModel):
    detail: list[dict[str, Any]] | ErrorDetail = Field(
        description="pydantic's list of field errors, or the envelope/PX4 refusal"
    )
