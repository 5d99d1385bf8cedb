"""The vehicle state snapshot the link fills: one frozen dataclass per wire model of
skyhelm_wire.state, generated from it by `python -m tools.gen_link_state`; do not edit.
tests/link/test_snapshot.py fails when it is not current."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from server.link.codec.signing import SigningStats


@dataclass(frozen=True)
class PositionNedState:
    """As the wire's PositionNedOut."""

    north_m: float
    east_m: float
    down_m: float


@dataclass(frozen=True)
class VelocityNedState:
    """As the wire's VelocityNedOut."""

    north_m_s: float
    east_m_s: float
    down_m_s: float


@dataclass(frozen=True)
class GlobalState:
    """As the wire's GlobalOut."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    alt_rel_m: float


@dataclass(frozen=True)
class AttitudeState:
    """As the wire's AttitudeOut."""

    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    rollspeed_deg_s: float
    pitchspeed_deg_s: float
    yawspeed_deg_s: float


@dataclass(frozen=True)
class BatteryState:
    """As the wire's BatteryOut."""

    voltage_v: float | None
    current_a: float | None
    remaining_pct: float | None
    # BATTERY_STATUS.current_consumed
    consumed_mah: float | None = None
    # the vehicle's own estimate (BATTERY_STATUS.time_remaining)
    time_remaining_s: float | None = None


@dataclass(frozen=True)
class EstimatorState:
    """ESTIMATOR_STATUS: the flags set and the test ratios PX4 checks its innovations against (1.0
    is the limit)."""

    # ESTIMATOR_STATUS flags set, without ESTIMATOR_
    flags: tuple[str, ...]
    # attitude, horizontal velocity and position valid
    healthy: bool
    pos_horiz_ratio: float | None
    pos_vert_ratio: float | None
    mag_ratio: float | None


@dataclass(frozen=True)
class GpsState:
    """As the wire's GpsOut."""

    fix_type: str
    satellites: int
    hdop: float | None


@dataclass(frozen=True)
class HomeState:
    """As the wire's HomeOut."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    north_m: float
    east_m: float
    down_m: float


@dataclass(frozen=True)
class OriginState:
    """As the wire's OriginOut."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float


@dataclass(frozen=True)
class StatusText:
    """As the wire's StatusTextOut."""

    time_s: float
    severity: str
    text: str


@dataclass(frozen=True)
class ArmingCheck:
    """One check PX4 reports failing or warning about, in its words."""

    # PX4's words
    text: str
    # PX4's log level; ERROR keeps the modes it concerns from arming
    severity: str
    # the modes it concerns (empty: not told)
    modes: tuple[str, ...]
    # PX4's health component it belongs to
    component: str | None
    kind: Literal["arming_check", "health"]


@dataclass(frozen=True)
class ArmingChecksState:
    """Ready to arm in the mode flown, and why not."""

    # arming would pass PX4's checks in `mode` (null: not told yet)
    ready: bool | None
    # the mode judged: the one the vehicle flies
    mode: str
    # events: PX4's arming-check report; sys_status: only SYS_STATUS's pre-arm and sensor health
    # bits (no events metadata)
    source: Literal["events", "sys_status"]
    # the modes PX4 would arm in now
    can_arm_modes: tuple[str, ...]
    # the failing checks (and warnings) that concern `mode`, errors first
    reasons: tuple[ArmingCheck, ...]
    # the checks that concern only other modes
    other_reasons: tuple[ArmingCheck, ...]
    # ready: arm, takeoff and an offboard start would be taken; arm_switches_mode: PX4 refuses
    # `mode` for its own checks only and SkyHelm's arm switches to `arm_switches_to` first, where
    # PX4 would arm; not_ready: see `reasons` and `waiting_for` (null: not told yet)
    verdict: Literal["ready", "arm_switches_mode", "not_ready"] | None = None
    # the mode SkyHelm's arm switches to before arming (null: arms in `mode`)
    arm_switches_to: str | None = None
    # what a takeoff or an offboard start still needs (home position, position estimate)
    waiting_for: tuple[str, ...] = ()


@dataclass(frozen=True)
class StreamStats:
    """Setpoint stream figures since it started; intervals from a bounded recent window."""

    active: bool = False
    rate_hz: float = 0.0
    interval_p50_ms: float | None = None
    interval_p99_ms: float | None = None
    max_gap_ms: float | None = None
    gaps: int = 0
    sent: int = 0
    since_last_ms: float | None = None
    # who sends the stream's frames now: 'process' (the setpoint sender process), 'thread' (the
    # server's sender thread: no process, or it failed), 'loop' or 'none' (stopped)
    sender: str = "none"
    # setpoint sender processes started after a fault
    sender_restarts: int = 0
    # the sender process's last fault and its cause (null: none)
    sender_fault: str | None = None


@dataclass(frozen=True)
class LinkQuality:
    """How well one vehicle is heard: the figures behind the lost verdict and the warning."""

    # since the vehicle's last valid frame
    silent_s: float
    # the silence that makes it lost: silence_timeout_s while it streams, heartbeat_timeout_s
    # otherwise
    lost_after_s: float
    # valid frames a second from the vehicle
    rate_hz: float
    # vehicle -> server frames lost over the last 5 s (sequence numbers)
    loss_in_pct: float | None
    # server -> vehicle frames lost over the last 5 s, as the vehicle reports it (PX4's
    # LINK_NODE_STATUS); null where it does not
    loss_out_pct: float | None
    heartbeat_age_s: float
    # a warning before the verdict: see warnings
    degraded: bool
    causes: tuple[Literal["silence", "loss_in", "loss_out", "heartbeat"], ...]
    warnings: tuple[str, ...]


@dataclass(frozen=True)
class LinkStats:
    """A link's traffic: what came in, what went out, what was lost or broken."""

    url: str
    # at least one vehicle on the link is heard (not silent)
    connected: bool
    frames_in: int
    frames_out: int
    bytes_in: int
    bytes_out: int
    # sequence gaps, per source system and component
    lost_frames: int
    # bad CRC, garbage, truncated frames: counted and dropped
    bad_frames: int
    # null before the first vehicle HEARTBEAT
    last_heartbeat_age_s: float | None
    reconnects: int
    signing: SigningStats | None = None
    # frames whose message id cannot be CRC-checked: counted and dropped
    unverified_frames: int = 0


@dataclass(frozen=True, kw_only=True)
class VehicleState:
    """A vehicle's state: one snapshot of everything the link knows of it."""

    sysid: int
    compid: int
    mav_type: str
    autopilot: str
    connected: bool
    last_heartbeat_age_s: float
    mode: str
    user_mode: str | None
    armed: bool
    # PX4's pre-arm bit: arming would pass its checks in the current mode
    ready_to_arm: bool | None
    system_status: str
    landed_state: Literal["UNDEFINED", "ON_GROUND", "IN_AIR", "TAKEOFF", "LANDING"]
    vtol_state: Literal["UNDEFINED", "MC", "FW", "TRANSITION_TO_FW", "TRANSITION_TO_MC"]
    # metres north, east and down of the estimator's local origin (PX4's EKF origin, the state's
    # `origin`: set where the estimator first had a position, normally where the vehicle was
    # switched on, or by POST /origin), not of home or of where a flight started: a script that
    # flies a leg reads it at the start and compares with that
    position_ned: PositionNedState | None
    velocity_ned: VelocityNedState | None
    global_position: GlobalState | None
    attitude: AttitudeState | None
    ground_speed_m_s: float | None
    air_speed_m_s: float | None
    climb_rate_m_s: float | None
    heading_deg: float | None
    battery: BatteryState | None
    gps: GpsState | None
    home: HomeState | None
    origin: OriginState | None
    # the streamed setpoint, offsets resolved
    setpoint: dict[str, object] | None
    target_ned: PositionNedState | None
    stream: StreamStats
    actuator_outputs: tuple[float, ...]
    statustext: tuple[StatusText, ...]
    rtl_phase: str | None
    link: LinkStats
    # time.monotonic() of the newest telemetry
    updated_s: float
    # fields not current: all while the link is lost, those not reported again since it came back
    # (mode reads UNKNOWN until it is)
    stale: tuple[str, ...] = ()
    estimator: EstimatorState | None = None
    # SYS_STATUS sensors present and enabled but not healthy
    sensors_unhealthy: tuple[str, ...] | None = None
    # seconds since each source message (by MAVLink name) was last received
    message_ages_s: dict[str, float] = field(default_factory=dict)
    link_quality: LinkQuality | None = None
    # how the server noticed the vehicle's loss, while `connected` is false ("nothing heard for
    # 1.0 s", "simulated vehicle's process ended (killed by SIGKILL)"); null while it is connected
    lost_reason: str | None = None
    # ready to fly: PX4's arming checks for the mode flown, and why not
    arming_checks: ArmingChecksState | None = None
    # telemetry streams the vehicle refused to send
    telemetry_refused: tuple[str, ...] = ()


# VehicleState's fields the API writes under the wire's name for them (its alias or
# its field name), where the snapshot's differs
API_NAMES: dict[str, str] = {
    "mav_type": "type",
    "global_position": "global",
}


__all__ = [
    "API_NAMES",
    "ArmingCheck",
    "ArmingChecksState",
    "AttitudeState",
    "BatteryState",
    "EstimatorState",
    "GlobalState",
    "GpsState",
    "HomeState",
    "LinkQuality",
    "LinkStats",
    "OriginState",
    "PositionNedState",
    "StatusText",
    "StreamStats",
    "VehicleState",
    "VelocityNedState",
]
