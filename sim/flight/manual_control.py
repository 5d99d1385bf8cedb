"""Stick input of the simulated vehicle, after PX4's manual control path.

- `stick_sample`: MANUAL_CONTROL as mavlink_receiver reads it (x pitch, y roll, z throttle
  0..1000, r yaw; out-of-range axes stay 0); the receiver's ManualControlReceiver feeds it.
- `ManualControlSelector`: which input is used, by COM_RC_IN_MODE (manual_control's
  ManualControlSelector); an input older than COM_RC_LOSS_T is no input.
- `ManualFlight`: sticks -> setpoint in the manual modes, after flight_mode_manager's
  FlightTaskManualPosition (POSCTL: velocity), FlightTaskManualAltitude (ALTCTL: tilt and
  climb rate) and mc_att_control's stabilized path (STABILIZED: attitude and throttle).

The sim has no RC receiver: every input comes from a MAVLink link.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from sim.lib import modes
from sim.lib.modes import Px4Mode
from sim.lib.numeric import clamp
from sim.lib.params import ParamReader
from sim.lib.quat import quat_from_euler, wrap_pi, yaw_from_quat
from sim.lib.topics import AttitudeSetpoint, ControlSetpoint, TrajectorySetpoint, VehicleStateTruth
from sim.physics.rigid_body import GRAVITY_M_S2

# manual_control_setpoint_s data sources
SOURCE_UNKNOWN = 0
SOURCE_RC = 1
SOURCE_MAVLINK_0 = 2

# FlightTaskManualAltitude::_checkTakeoff: throttle stick above this (of [-1, 1]) takes off
TAKEOFF_STICK = 0.3
# Modes whose setpoint comes from the sticks (mode_req_manual_control in PX4).
MANUAL_CONTROL_MODES = frozenset(
    {modes.MANUAL, modes.STABILIZED, modes.ACRO, modes.ALTCTL, modes.POSCTL}
)


class RcInMode(IntEnum):
    """COM_RC_IN_MODE values (PX4 v1.16; default 3)."""

    RC_TRANSMITTER_ONLY = 0
    JOYSTICK_ONLY = 1
    RC_AND_JOYSTICK_WITH_FALLBACK = 2
    RC_OR_JOYSTICK_KEEP_FIRST = 3
    STICK_INPUT_DISABLED = 4


@dataclass(frozen=True)
class StickSample:
    """PX4 `manual_control_setpoint`: each axis in [-1, 1] (throttle -1 = stick down)."""

    roll: float
    pitch: float
    yaw: float
    throttle: float
    received_s: float
    data_source: int


def stick_sample(
    x: int, y: int, z: int, r: int, received_s: float, data_source: int
) -> StickSample:
    """MavlinkReceiver::handle_message_manual_control: an axis outside its range stays 0."""
    pitch = x / 1000.0 if -1000 <= x <= 1000 else 0.0
    roll = y / 1000.0 if -1000 <= y <= 1000 else 0.0
    # throttle is sent 0..1000 for backwards compatibility, used as [-1, 1]
    throttle = z / 500.0 - 1.0 if 0 <= z <= 1000 else 0.0
    yaw = r / 1000.0 if -1000 <= r <= 1000 else 0.0
    return StickSample(roll, pitch, yaw, throttle, received_s, data_source)


class ManualControlSelector:
    """manual_control's ManualControlSelector: the input in use, chosen by COM_RC_IN_MODE."""

    def __init__(self, params: ParamReader) -> None:
        self._params = params
        self.setpoint: StickSample | None = None
        self.first_valid_source = SOURCE_UNKNOWN
        self.last_valid_s = -math.inf  # when an input was last taken

    def _timeout_s(self) -> float:
        return float(self._params.get("COM_RC_LOSS_T"))

    def _source_matches(self, source: int) -> bool:
        mode = int(self._params.get("COM_RC_IN_MODE"))
        if mode == RcInMode.RC_TRANSMITTER_ONLY:
            return source == SOURCE_RC
        if mode == RcInMode.JOYSTICK_ONLY:
            return source >= SOURCE_MAVLINK_0
        if mode == RcInMode.RC_AND_JOYSTICK_WITH_FALLBACK:
            return True
        if mode == RcInMode.RC_OR_JOYSTICK_KEEP_FIRST:
            first = self.first_valid_source
            return first in (SOURCE_UNKNOWN, source)
        return False  # STICK_INPUT_DISABLED

    def _is_valid(self, sample: StickSample, now_s: float) -> bool:
        fresh = 0.0 <= now_s - sample.received_s < self._timeout_s()
        return fresh and self._source_matches(sample.data_source)

    def current(self, now_s: float) -> StickSample | None:
        """The input in use, or None when there is none (manual control lost)."""
        if self.setpoint is not None and not self._is_valid(self.setpoint, now_s):
            self.setpoint = None
        return self.setpoint

    def take(self, sample: StickSample, now_s: float) -> None:
        current = self.current(now_s)
        same_source = current is not None and current.data_source == sample.data_source
        if self._is_valid(sample, now_s) and (same_source or current is None):
            self.setpoint = sample
            self.last_valid_s = now_s
            if self.first_valid_source == SOURCE_UNKNOWN:
                self.first_valid_source = sample.data_source


def expo(value: float, e: float) -> float:
    """PX4 math::expo: linear at e = 0, cubic at e = 1."""
    x = clamp(value, -1.0, 1.0)
    ec = clamp(e, 0.0, 1.0)
    return (1.0 - ec) * x + ec * x * x * x


def deadzone(value: float, dz: float) -> float:
    """PX4 math::deadzone: zero inside ±dz, linear and continuous outside."""
    x = clamp(value, -1.0, 1.0)
    dzc = clamp(dz, 0.0, 0.99)
    if abs(x) <= dzc:
        return 0.0
    return (x - math.copysign(dzc, x)) / (1.0 - dzc)


def expo_deadzone(value: float, e: float, dz: float) -> float:
    return expo(deadzone(value, dz), e)


@dataclass(frozen=True)
class Sticks:
    """flight_mode_manager's Sticks: (pitch, roll, -throttle, yaw) with deadzone and expo."""

    pitch: float
    roll: float
    down: float  # -throttle: positive is stick down (descend)
    yaw: float

    @classmethod
    def from_sample(cls, sample: StickSample, params: ParamReader) -> Sticks:
        dz = params.get("MPC_HOLD_DZ")
        xy_e = params.get("MPC_XY_MAN_EXPO")
        return cls(
            expo_deadzone(sample.pitch, xy_e, dz),
            expo_deadzone(sample.roll, xy_e, dz),
            expo_deadzone(-sample.throttle, params.get("MPC_Z_MAN_EXPO"), dz),
            expo_deadzone(sample.yaw, params.get("MPC_YAW_EXPO"), dz),
        )


class ManualFlight:
    """Sticks -> setpoint for one manual mode; keeps the locks (position, altitude, yaw)
    that centred sticks hold, like PX4's manual flight tasks."""

    def __init__(self, params: ParamReader) -> None:
        self._params = params
        self.reset()

    def reset(self) -> None:
        self._lock_xy: list[float] | None = None
        self._lock_down_m: float | None = None
        self._yaw_sp_rad: float | None = None
        self._taken_off = False

    def setpoint(
        self,
        mode: Px4Mode,
        sample: StickSample,
        truth: VehicleStateTruth,
        dt_s: float,
        landed: bool,
    ) -> ControlSetpoint | None:
        """None: motors idle (landed with the throttle stick not raised to take off)."""
        p = self._params
        raw_down = -sample.throttle
        if landed and raw_down > -TAKEOFF_STICK:
            self.reset()
            return None
        sticks = Sticks.from_sample(sample, p)
        yaw_now = yaw_from_quat(truth.q_wxyz)
        yawspeed = sticks.yaw * math.radians(p.get("MPC_MAN_Y_MAX"))
        yaw_sp = self._yaw_setpoint(yawspeed, yaw_now, dt_s)
        if mode == modes.STABILIZED or mode not in (modes.POSCTL, modes.ALTCTL):
            return self._stabilized(sample, sticks, yaw_sp)
        vz = self._climb_rate(sticks)
        pos_down = self._altitude_lock(vz, truth)
        if mode == modes.POSCTL:
            vx, vy = self._horizontal_velocity(sticks, yaw_now)
            lock = self._position_lock(vx, vy, truth)
            return TrajectorySetpoint(
                position_ned_m=[lock[0], lock[1], pos_down],
                velocity_ned_m_s=[_unless_locked(vx, lock[0]), _unless_locked(vy, lock[1]),
                                  _unless_locked(vz, pos_down)],
                yaw_rad=yaw_sp,
            )
        ax, ay = self._tilt_acceleration(sticks, yaw_now)
        return TrajectorySetpoint(
            position_ned_m=[math.nan, math.nan, pos_down],
            velocity_ned_m_s=[math.nan, math.nan, _unless_locked(vz, pos_down)],
            acceleration_ned_m_s2=[ax, ay, math.nan],
            yaw_rad=yaw_sp,
        )

    # -- axes ---------------------------------------------------------------------------

    def _yaw_setpoint(self, yawspeed_rad_s: float, yaw_now: float, dt_s: float) -> float:
        """StickYaw: the yaw setpoint moves with the stick and is held when it is centred."""
        if self._yaw_sp_rad is None or abs(wrap_pi(self._yaw_sp_rad - yaw_now)) > 0.5:
            self._yaw_sp_rad = yaw_now
        self._yaw_sp_rad = wrap_pi(self._yaw_sp_rad + yawspeed_rad_s * dt_s)
        return self._yaw_sp_rad

    def _climb_rate(self, sticks: Sticks) -> float:
        """FlightTaskManualAltitude::_scaleSticks: down is positive, up and down limits
        MPC_Z_VEL_MAX_UP and MPC_Z_VEL_MAX_DN."""
        p = self._params
        limit = p.get("MPC_Z_VEL_MAX_DN") if sticks.down > 0.0 else p.get("MPC_Z_VEL_MAX_UP")
        return float(limit) * sticks.down

    def _altitude_lock(self, vz: float, truth: VehicleStateTruth) -> float:
        """Centred throttle holds the altitude where the vehicle stopped climbing."""
        if vz != 0.0:
            self._lock_down_m = None
            return math.nan
        if self._lock_down_m is None and abs(truth.velocity_ned_m_s[2]) < self._params.get(
            "MPC_HOLD_MAX_Z"
        ):
            self._lock_down_m = truth.position_ned_m[2]
        return math.nan if self._lock_down_m is None else self._lock_down_m

    def _horizontal_velocity(self, sticks: Sticks, yaw_rad: float) -> tuple[float, float]:
        """FlightTaskManualPosition::_scaleSticks: stick vector limited to unit length,
        times MPC_VEL_MANUAL, rotated from the heading frame to NED."""
        forward, right = sticks.pitch, sticks.roll
        length = math.hypot(forward, right)
        if length > 1.0:
            forward, right = forward / length, right / length
        scale = self._params.get("MPC_VEL_MANUAL")
        forward, right = forward * scale, right * scale
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        return forward * c - right * s, forward * s + right * c

    def _position_lock(self, vx: float, vy: float, truth: VehicleStateTruth) -> list[float]:
        """FlightTaskManualPosition::_updateXYlock: centred sticks hold the position once
        the vehicle slowed below MPC_HOLD_MAX_XY."""
        if vx != 0.0 or vy != 0.0:
            self._lock_xy = None
            return [math.nan, math.nan]
        speed = math.hypot(*truth.velocity_ned_m_s[:2])
        if self._lock_xy is None and speed < self._params.get("MPC_HOLD_MAX_XY"):
            self._lock_xy = list(truth.position_ned_m[:2])
        return [math.nan, math.nan] if self._lock_xy is None else list(self._lock_xy)

    def _tilt_acceleration(self, sticks: Sticks, yaw_rad: float) -> tuple[float, float]:
        """StickTiltXY: the stick tilts the vehicle up to MPC_MAN_TILT_MAX, which is the
        horizontal acceleration g·tan(tilt) in the stick's direction."""
        forward, right = sticks.pitch, sticks.roll
        length = math.hypot(forward, right)
        if length > 1.0:
            forward, right = forward / length, right / length
        tilt_max = math.radians(self._params.get("MPC_MAN_TILT_MAX"))
        a_fwd = GRAVITY_M_S2 * math.tan(forward * tilt_max)
        a_right = GRAVITY_M_S2 * math.tan(right * tilt_max)
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        return a_fwd * c - a_right * s, a_fwd * s + a_right * c

    def _stabilized(self, sample: StickSample, sticks: Sticks, yaw_sp: float) -> AttitudeSetpoint:
        """mc_att_control's stabilized path: roll and pitch from the sticks (forward stick
        pitches the nose down), thrust from the throttle curve."""
        tilt_max = math.radians(self._params.get("MPC_MAN_TILT_MAX"))
        roll = sample.roll * tilt_max
        pitch = -sample.pitch * tilt_max
        thrust = self._throttle_curve((sample.throttle + 1.0) / 2.0)
        return AttitudeSetpoint(quat_from_euler(roll, pitch, yaw_sp), (0.0, 0.0, -thrust))

    def _throttle_curve(self, stick_0_1: float) -> float:
        """MPC_THR_CURVE 0: the stick's middle is hover thrust, its ends MPC_MANTHR_MIN and
        MPC_THR_MAX."""
        p = self._params
        hover = p.get("MPC_THR_HOVER")
        low, high = p.get("MPC_MANTHR_MIN"), p.get("MPC_THR_MAX")
        if stick_0_1 < 0.5:
            return float(low + (hover - low) * stick_0_1 * 2.0)
        return float(hover + (high - hover) * (stick_0_1 - 0.5) * 2.0)


def _unless_locked(velocity: float, locked_at: float) -> float:
    """The stick's velocity, or 0 where that axis holds a locked position."""
    return velocity if math.isnan(locked_at) else 0.0
