"""MAVLink link layer: connections, vehicles, commands, setpoints and telemetry state.

The public surface: ``Link`` and ``Vehicle``, the setpoint kinds and their encoding, the
state a vehicle reports, and what its operations return. Nothing of HTTP, pydantic or
viser is imported here.
"""

from . import setpoints as _setpoints
from .commands import CommandOutcome, CommandResult
from .events import VehicleEvent
from .link import Link
from .link_stats import LinkStats
from .liveness import LinkQuality
from .manual_control import Sticks
from .modes import PX4_MODE_NAMES
from .params import ParamError
from .setpoint_checks import Envelope, SetpointRejected, check
from .setpoints import *  # noqa: F403  (the setpoint kinds, encode, resolve, describe)
from .state import (
    AttitudeState,
    BatteryState,
    EstimatorState,
    GlobalState,
    GpsState,
    HomeState,
    OriginState,
    PositionNedState,
    StateSubscription,
    StatusText,
    StreamStats,
    VehicleState,
    VelocityNedState,
)
from .vehicle import Vehicle

__all__ = [
    "PX4_MODE_NAMES",
    "AttitudeState",
    "BatteryState",
    "CommandOutcome",
    "CommandResult",
    "Envelope",
    "EstimatorState",
    "GlobalState",
    "GpsState",
    "HomeState",
    "Link",
    "LinkQuality",
    "LinkStats",
    "OriginState",
    "ParamError",
    "PositionNedState",
    "SetpointRejected",
    "StateSubscription",
    "StatusText",
    "StreamStats",
    "Sticks",
    "Vehicle",
    "VehicleEvent",
    "VehicleState",
    "VelocityNedState",
    "check",
    *_setpoints.__all__,
]
