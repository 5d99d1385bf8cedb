"""Offboard setpoints in: SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT and
SET_ATTITUDE_TARGET, checked and converted as PX4's mavlink_receiver does.

Setpoints are never acked; a refused one is reported only by STATUSTEXT. An accepted one
goes to the commander as proof of offboard life, in any mode.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import development as mavlink

from sim.flight.commander_failsafe import MAV_SEVERITY_CRITICAL
from sim.lib.quat import quat_from_yaw, rotate_body_to_ned, yaw_from_quat
from sim.lib.topics import AttitudeSetpoint, ControlSetpoint, RatesSetpoint, TrajectorySetpoint
from sim.mavlink.vehicle_interface import Link, Message, VehicleInterface

# SET_POSITION_TARGET_* type_mask bits (POSITION_TARGET_TYPEMASK).
IGNORE_PX, IGNORE_PY, IGNORE_PZ = 1, 2, 4
IGNORE_VX, IGNORE_VY, IGNORE_VZ = 8, 16, 32
IGNORE_AX, IGNORE_AY, IGNORE_AZ = 64, 128, 256
FORCE_SET = 512
IGNORE_YAW = 1024
IGNORE_YAW_RATE = 2048
# SET_ATTITUDE_TARGET type_mask bits (ATTITUDE_TARGET_TYPEMASK).
IGNORE_ROLL_RATE, IGNORE_PITCH_RATE, IGNORE_YAW_RATE_BODY = 1, 2, 4
IGNORE_THROTTLE = 64
IGNORE_ATTITUDE = 128

_IGNORE_RATES = IGNORE_ROLL_RATE | IGNORE_PITCH_RATE | IGNORE_YAW_RATE_BODY
_LOCAL_FRAMES = (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_NED)
_GLOBAL_FRAMES = (mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                  mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)


def _nan_if(ignored: bool, value: float) -> float:
    return math.nan if ignored else float(value)


def _vector(
    mask: int, bits: tuple[int, int, int], values: tuple[float, float, float]
) -> list[float]:
    return [_nan_if(bool(mask & bit), value) for bit, value in zip(bits, values, strict=True)]


def _velocity_and_accel(msg: Message) -> tuple[list[float], list[float]]:
    mask = msg.type_mask
    velocity = _vector(mask, (IGNORE_VX, IGNORE_VY, IGNORE_VZ), (msg.vx, msg.vy, msg.vz))
    accel = _vector(mask, (IGNORE_AX, IGNORE_AY, IGNORE_AZ), (msg.afx, msg.afy, msg.afz))
    return velocity, accel


def _all_nan(v: list[float]) -> bool:
    return all(math.isnan(c) for c in v)


class OffboardSetpoints:
    def __init__(self, vehicle: VehicleInterface) -> None:
        self._v = vehicle

    def _refuse(self, message_name: str, reason: str) -> None:
        self._v.announce(MAV_SEVERITY_CRITICAL, f"{message_name} {reason}")

    def _accept(self, setpoint: ControlSetpoint) -> None:
        self._v.commander.on_offboard_setpoint(setpoint, self._v.now_s)

    def _frame_supported(self, msg: Message, frames: tuple[int, ...]) -> bool:
        if msg.coordinate_frame in frames:
            return True
        self._refuse(msg.get_type(), f"coordinate frame {msg.coordinate_frame} unsupported")
        return False

    def handle_local_ned(self, link: Link, msg: Message) -> None:
        if not self._frame_supported(msg, _LOCAL_FRAMES):
            return
        position = _vector(msg.type_mask, (IGNORE_PX, IGNORE_PY, IGNORE_PZ), (msg.x, msg.y, msg.z))
        velocity, accel = _velocity_and_accel(msg)
        if msg.coordinate_frame == mavlink.MAV_FRAME_BODY_NED:
            q = self._v.truth.q_wxyz
            position = [math.nan] * 3
            velocity = list(rotate_body_to_ned(quat_from_yaw(yaw_from_quat(q)), velocity))
            accel = list(rotate_body_to_ned(q, accel))
        self._publish_trajectory(msg, position, velocity, accel)

    def handle_global_int(self, link: Link, msg: Message) -> None:
        if not self._frame_supported(msg, _GLOBAL_FRAMES):
            return
        frame = msg.coordinate_frame
        v = self._v
        if not v.ready:
            return  # no global position yet: PX4 drops these silently
        mask = msg.type_mask
        position = [math.nan] * 3
        if not mask & (IGNORE_PX | IGNORE_PY | IGNORE_PZ):
            north, east, _ = v.origin.to_ned(msg.lat_int * 1e-7, msg.lon_int * 1e-7, v.origin.alt_m)
            if frame == mavlink.MAV_FRAME_GLOBAL_INT:
                down = v.origin.down_of_altitude(msg.alt)
            elif frame == mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT:
                down = v.commander.home.position_ned_m[2] - msg.alt
            else:
                down = -msg.alt  # flat terrain at local down 0
            position = [north, east, down]
        velocity, accel = _velocity_and_accel(msg)
        self._publish_trajectory(msg, position, velocity, accel)

    def _publish_trajectory(self, msg: Message, position: list[float],
                            velocity: list[float], accel: list[float]) -> None:
        name, mask = msg.get_type(), msg.type_mask
        if not _all_nan(accel) and mask & FORCE_SET:
            self._refuse(name, "force not supported")
            return
        if _all_nan(position) and _all_nan(velocity) and _all_nan(accel):
            self._refuse(name, "invalid")
            return
        self._accept(TrajectorySetpoint(
            position_ned_m=position,
            velocity_ned_m_s=velocity,
            acceleration_ned_m_s2=accel,
            yaw_rad=_nan_if(bool(mask & IGNORE_YAW), msg.yaw),
            yawspeed_rad_s=_nan_if(bool(mask & IGNORE_YAW_RATE), msg.yaw_rate),
        ))

    def handle_attitude_target(self, link: Link, msg: Message) -> None:
        mask = msg.type_mask
        rates_ignored = mask & _IGNORE_RATES == _IGNORE_RATES
        attitude_ignored = bool(mask & IGNORE_ATTITUDE)
        if rates_ignored and attitude_ignored:
            self._refuse("SET_ATTITUDE_TARGET", "invalid")
            return
        throttle = self._v.params.get("MPC_THR_HOVER") if mask & IGNORE_THROTTLE else msg.thrust
        thrust = self._thrust_body(throttle)
        setpoint: ControlSetpoint
        if not rates_ignored:
            rates = _vector(mask, (IGNORE_ROLL_RATE, IGNORE_PITCH_RATE, IGNORE_YAW_RATE_BODY),
                            (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate))
            r = tuple(0.0 if math.isnan(c) else c for c in rates)
            setpoint = RatesSetpoint(rates_rad_s=(r[0], r[1], r[2]), thrust_body=thrust)
        else:
            q = msg.q
            setpoint = AttitudeSetpoint(q_wxyz=(q[0], q[1], q[2], q[3]), thrust_body=thrust)
        self._accept(setpoint)

    def _thrust_body(self, throttle: float) -> tuple[float, float, float]:
        """Multicopter thrust points along -z body, fixed wing along +x."""
        if self._v.model.in_fixed_wing_flight:
            return (throttle, 0.0, 0.0)
        return (0.0, 0.0, -throttle)
