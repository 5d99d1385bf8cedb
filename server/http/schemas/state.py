"""The vehicle state and summary as the API returns them (GET and the WebSocket)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from server.http.schemas.control import LeaseStatusOut
from server.http.schemas.setpoints import SetpointBody
from server.http.schemas.signing import SigningOut


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
    consumed_mah: float | None = Field(None, description="BATTERY_STATUS.current_consumed")
    time_remaining_s: float | None = Field(
        None, description="the vehicle's own estimate (BATTERY_STATUS.time_remaining)"
    )


class EstimatorOut(_Out):
    flags: list[str] = Field(description="ESTIMATOR_STATUS flags set, without ESTIMATOR_")
    healthy: bool = Field(description="attitude, horizontal velocity and position valid")
    pos_horiz_ratio: float | None
    pos_vert_ratio: float | None
    mag_ratio: float | None


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
    unverified_frames: int = Field(
        0, description="frames whose message id cannot be CRC-checked: counted and dropped"
    )
    last_heartbeat_age_s: float | None
    reconnects: int = 0
    signing: SigningOut | None = None


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
    ready_to_arm: bool | None = Field(
        description="PX4's pre-arm bit: arming would pass its checks in the current mode"
    )
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
    setpoint: SetpointBody | None = Field(description="the streamed setpoint, offsets resolved")
    target_ned: PositionNedOut | None
    stream: StreamOut
    lease: LeaseStatusOut
    actuator_outputs: list[float | None]
    statustext: list[StatusTextOut]
    rtl_phase: str | None
    link: LinkOut
    updated_s: float = Field(description="time.monotonic() of the newest telemetry")
    stale: list[str] = Field(
        default_factory=list,
        description="fields not current: all while the link is lost, those not reported "
        "again since it came back (mode reads UNKNOWN until it is)",
    )
    estimator: EstimatorOut | None = None
    sensors_unhealthy: list[str] | None = Field(
        None, description="SYS_STATUS sensors present and enabled but not healthy"
    )
    message_ages_s: dict[str, float] = Field(
        default_factory=dict,
        description="seconds since each source message (by MAVLink name) was last received",
    )
