"""Messages passed between the simulated vehicle's modules, after PX4's uORB topics.

The navigator, commander and offboard receiver write setpoints; the controllers read them;
the airframe model publishes its state. All frames are NED (north, east, down) in metres,
bodies are FRD (forward, right, down), angles in radians, quaternions (w, x, y, z) rotate
body to NED. NaN in a setpoint field means "not controlled" (PX4's convention).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

NAN = math.nan


def _nan3() -> list[float]:
    return [NAN, NAN, NAN]


@dataclass
class TrajectorySetpoint:
    """PX4 `trajectory_setpoint`: what the position/velocity controller tracks.

    Position alone: fly there. Position + velocity (+ acceleration): velocity and
    acceleration are feed-forward. Velocity alone, acceleration alone: track those.
    The speed limits are PX4's `vehicle_constraints` (NaN = airframe default).
    On a fixed wing (or VTOL in FW) a position means "fly there, then circle it"
    with `loiter_radius_m`.
    """

    position_ned_m: list[float] = field(default_factory=_nan3)
    velocity_ned_m_s: list[float] = field(default_factory=_nan3)
    acceleration_ned_m_s2: list[float] = field(default_factory=_nan3)
    yaw_rad: float = NAN
    yawspeed_rad_s: float = NAN
    max_speed_xy_m_s: float = NAN
    max_speed_up_m_s: float = NAN
    max_speed_down_m_s: float = NAN
    loiter_radius_m: float = NAN


@dataclass
class LandingStatus:
    """What PX4's multicopter land detector and position controller tell each other.

    One way `vehicle_land_detected` (landed, maybe_landed, ground_contact); the other the
    collective thrust setpoint, the vertical velocity setpoint, whether the climb rate is
    controlled, the hover thrust and the takeoff state (`takeoff_status`).
    """

    landed: bool = True
    maybe_landed: bool = True
    ground_contact: bool = True
    thrust_setpoint: float = 0.0
    velocity_setpoint_down_m_s: float = NAN
    climb_rate_controlled: bool = True
    hover_thrust: float = 0.5
    takeoff_state: int = 0
    # set by the vehicle's land detector; a model flown alone (no detector) skips the
    # takeoff handling, as PX4's controller does when told to (COM_THROW_EN's skip)
    detector_attached: bool = False


@dataclass
class AttitudeSetpoint:
    """PX4 `vehicle_attitude_setpoint`: attitude quaternion and normalised body thrust.

    Multicopter thrust is along -z body (thrust_body_n[2] in [-1, 0]); fixed wing along +x.
    """

    q_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    thrust_body: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass
class RatesSetpoint:
    """PX4 `vehicle_rates_setpoint`: body rates (roll, pitch, yaw) and normalised thrust."""

    rates_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    thrust_body: tuple[float, float, float] = (0.0, 0.0, 0.0)


ControlSetpoint = TrajectorySetpoint | AttitudeSetpoint | RatesSetpoint


class VtolState(IntEnum):
    """MAVLink MAV_VTOL_STATE, as in EXTENDED_SYS_STATE.vtol_state."""

    UNDEFINED = 0
    TRANSITION_TO_FW = 1
    TRANSITION_TO_MC = 2
    MC = 3
    FW = 4


@dataclass
class VehicleStateTruth:
    """The airframe model's true state, which the simulated estimator reports as is."""

    position_ned_m: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    velocity_ned_m_s: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    acceleration_ned_m_s2: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    q_wxyz: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0, 0.0])
    rates_body_rad_s: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    airspeed_m_s: float = 0.0
    on_ground: bool = True
