"""MAVLink link layer: connections, vehicles, commands, setpoints and telemetry state.

Nothing of HTTP, pydantic or viser is imported here.
"""

from .commands import CommandOutcome, CommandResult
from .events import VehicleEvent
from .link import Link
from .link_stats import LinkStats
from .modes import PX4_MODE_NAMES
from .params import ParamError
from .setpoint_checks import Envelope, SetpointRejected
from .setpoints import (
    AccelerationNed,
    Attitude,
    BodyRates,
    OffsetBody,
    OffsetNed,
    PositionGlobal,
    PositionNed,
    PositionVelocityNed,
    RawLocal,
    SentSetpoint,
    Setpoint,
    VelocityBody,
    VelocityNed,
)
from .state import (
    AttitudeState,
    BatteryState,
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
    "AccelerationNed",
    "Attitude",
    "AttitudeState",
    "BatteryState",
    "BodyRates",
    "CommandOutcome",
    "CommandResult",
    "Envelope",
    "GlobalState",
    "GpsState",
    "HomeState",
    "Link",
    "LinkStats",
    "OffsetBody",
    "OffsetNed",
    "OriginState",
    "ParamError",
    "PositionGlobal",
    "PositionNed",
    "PositionNedState",
    "PositionVelocityNed",
    "RawLocal",
    "SentSetpoint",
    "Setpoint",
    "SetpointRejected",
    "StateSubscription",
    "StatusText",
    "StreamStats",
    "Vehicle",
    "VehicleEvent",
    "VehicleState",
    "VelocityBody",
    "VelocityNed",
    "VelocityNedState",
]
