"""The vehicle state and summary as the API returns them (GET and the WebSocket)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

from skyhelm_wire.control import LeaseStatusOut
from skyhelm_wire.setpoints import SetpointBody
from skyhelm_wire.signing import SigningOut


class NanIsNull:
    """Marks a number the server always has, NaN while unknown; JSON has no NaN, so it
    travels as null. The link's snapshot (generated from these models by
    `python -m tools.gen_link_state`) holds it as a plain float."""


# a float on the server, null on the wire while it is NaN
FloatNaN = Annotated[float | None, NanIsNull()]


class _Out(BaseModel):
    model_config = ConfigDict(extra="ignore")


class PositionNedOut(_Out):
    north_m: FloatNaN
    east_m: FloatNaN
    down_m: FloatNaN


class VelocityNedOut(_Out):
    north_m_s: FloatNaN
    east_m_s: FloatNaN
    down_m_s: FloatNaN


class GlobalOut(_Out):
    lat_deg: FloatNaN
    lon_deg: FloatNaN
    alt_amsl_m: FloatNaN
    alt_rel_m: FloatNaN


class AttitudeOut(_Out):
    roll_deg: FloatNaN
    pitch_deg: FloatNaN
    yaw_deg: FloatNaN
    rollspeed_deg_s: FloatNaN
    pitchspeed_deg_s: FloatNaN
    yawspeed_deg_s: FloatNaN


class BatteryOut(_Out):
    voltage_v: float | None
    current_a: float | None
    remaining_pct: float | None
    consumed_mah: float | None = Field(None, description="BATTERY_STATUS.current_consumed")
    time_remaining_s: float | None = Field(
        None, description="the vehicle's own estimate (BATTERY_STATUS.time_remaining)"
    )


class EstimatorOut(_Out):
    """ESTIMATOR_STATUS: the flags set and the test ratios PX4 checks its innovations
    against (1.0 is the limit)."""

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
    lat_deg: FloatNaN
    lon_deg: FloatNaN
    alt_amsl_m: FloatNaN
    north_m: FloatNaN
    east_m: FloatNaN
    down_m: FloatNaN


class OriginOut(_Out):
    lat_deg: FloatNaN
    lon_deg: FloatNaN
    alt_amsl_m: FloatNaN


class StreamOut(_Out):
    """Setpoint stream figures since it started; intervals from a bounded recent window."""

    active: bool = False
    rate_hz: FloatNaN = 0.0
    interval_p50_ms: float | None = None
    interval_p99_ms: float | None = None
    max_gap_ms: float | None = None
    gaps: int = 0
    sent: int = 0
    since_last_ms: float | None = None
    sender: str = Field(
        default="none",
        description="who sends the stream's frames now: 'process' (the setpoint sender "
        "process), 'thread' (the server's sender thread: no process, or it failed), 'loop' "
        "or 'none' (stopped)")
    sender_restarts: int = Field(
        default=0, description="setpoint sender processes started after a fault")
    sender_fault: str | None = Field(
        default=None, description="the sender process's last fault and its cause (null: none)")


class LinkOut(_Out):
    """A link's traffic: what came in, what went out, what was lost or broken."""

    url: str
    connected: bool = Field(description="at least one vehicle on the link is heard (not silent)")
    frames_in: int
    frames_out: int
    bytes_in: int
    bytes_out: int
    lost_frames: int = Field(description="sequence gaps, per source system and component")
    bad_frames: int = Field(description="bad CRC, garbage, truncated frames: counted and dropped")
    last_heartbeat_age_s: float | None = Field(
        description="null before the first vehicle HEARTBEAT"
    )
    reconnects: int
    signing: SigningOut | None = None
    unverified_frames: int = Field(
        0, description="frames whose message id cannot be CRC-checked: counted and dropped"
    )


class LinkQualityOut(_Out):
    """How well one vehicle is heard: the figures behind the lost verdict and the warning."""

    silent_s: float = Field(description="since the vehicle's last valid frame")
    lost_after_s: float = Field(
        description="the silence that makes it lost: silence_timeout_s while it streams, "
        "heartbeat_timeout_s otherwise"
    )
    rate_hz: float = Field(description="valid frames a second from the vehicle")
    loss_in_pct: float | None = Field(
        description="vehicle -> server frames lost over the last 5 s (sequence numbers)"
    )
    loss_out_pct: float | None = Field(
        description="server -> vehicle frames lost over the last 5 s, as the vehicle "
        "reports it (PX4's LINK_NODE_STATUS); null where it does not"
    )
    heartbeat_age_s: float
    degraded: bool = Field(description="a warning before the verdict: see warnings")
    causes: list[Literal["silence", "loss_in", "loss_out", "heartbeat"]]
    warnings: list[str]


class StatusTextOut(_Out):
    time_s: float
    severity: str
    text: str


class ArmingCheckOut(_Out):
    """One check PX4 reports failing or warning about, in its words."""

    text: str = Field(description="PX4's words", examples=["No offboard signal"])
    severity: str = Field(
        description="PX4's log level; ERROR keeps the modes it concerns from arming",
        examples=["ERROR"],
    )
    modes: list[str] = Field(description="the modes it concerns (empty: not told)")
    component: str | None = Field(description="PX4's health component it belongs to")
    kind: Literal["arming_check", "health"]


class ArmingChecksOut(_Out):
    """Ready to arm in the mode flown, and why not."""

    ready: bool | None = Field(
        description="arming would pass PX4's checks in `mode` (null: not told yet)"
    )
    mode: str = Field(description="the mode judged: the one the vehicle flies")
    source: Literal["events", "sys_status"] = Field(
        description="events: PX4's arming-check report; sys_status: only SYS_STATUS's "
        "pre-arm and sensor health bits (no events metadata)"
    )
    can_arm_modes: list[str] = Field(description="the modes PX4 would arm in now")
    reasons: list[ArmingCheckOut] = Field(
        description="the failing checks (and warnings) that concern `mode`, errors first"
    )
    other_reasons: list[ArmingCheckOut] = Field(
        description="the checks that concern only other modes"
    )
    verdict: Literal["ready", "arm_switches_mode", "not_ready"] | None = Field(
        None,
        description="ready: arm, takeoff and an offboard start would be taken; "
        "arm_switches_mode: PX4 refuses `mode` for its own checks only and SkyHelm's arm "
        "switches to `arm_switches_to` first, where PX4 would arm; not_ready: see `reasons` "
        "and `waiting_for` (null: not told yet)",
    )
    arm_switches_to: str | None = Field(
        None, description="the mode SkyHelm's arm switches to before arming (null: arms in `mode`)"
    )
    waiting_for: list[str] = Field(
        default_factory=list,
        description="what a takeoff or an offboard start still needs "
        "(home position, position estimate)",
    )


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
    """A vehicle's state: one snapshot of everything the link knows of it."""

    model_config = ConfigDict(extra="ignore", populate_by_name=True)

    id: int
    sysid: int
    compid: int
    type: str
    autopilot: str
    connected: bool
    last_heartbeat_age_s: FloatNaN
    mode: str
    user_mode: str | None
    armed: bool
    ready_to_arm: bool | None = Field(
        description="PX4's pre-arm bit: arming would pass its checks in the current mode"
    )
    system_status: str
    landed_state: Literal["UNDEFINED", "ON_GROUND", "IN_AIR", "TAKEOFF", "LANDING"]
    vtol_state: Literal["UNDEFINED", "MC", "FW", "TRANSITION_TO_FW", "TRANSITION_TO_MC"]
    position_ned: PositionNedOut | None = Field(
        description="metres north, east and down of the estimator's local origin (PX4's EKF "
        "origin, the state's `origin`: set where the estimator first had a position, normally "
        "where the vehicle was switched on, or by POST /origin), not of home or of where a "
        "flight started: a script that flies a leg reads it at the start and compares with that"
    )
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
    actuator_outputs: list[FloatNaN]
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
    link_quality: LinkQualityOut | None = None
    lost_reason: str | None = Field(
        None,
        description="how the server noticed the vehicle's loss, while `connected` is false "
        "(\"nothing heard for 1.0 s\", \"simulated vehicle's process ended (killed by "
        "SIGKILL)\"); null while it is connected",
    )
    arming_checks: ArmingChecksOut | None = Field(
        None, description="ready to fly: PX4's arming checks for the mode flown, and why not"
    )
