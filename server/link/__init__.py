"""MAVLink link layer: connections, vehicles, commands, setpoints and telemetry state.

The public surface: ``Link`` and ``Vehicle``, the setpoint kinds and their encoding, the
state a vehicle reports, and what its operations return. Nothing of HTTP, pydantic or
viser is imported here.
"""

from server.link.codec import setpoints as _setpoints
from server.link.codec.commands import CommandOutcome, CommandResult
from server.link.codec.modes import PX4_MODE_NAMES
from server.link.codec.setpoint_checks import Envelope, SetpointRejected, check
from server.link.codec.setpoints import *  # noqa: F403  (the setpoint kinds, encode, resolve, describe)
from server.link.core.events import VehicleEvent
from server.link.core.link_stats import LinkStats
from server.link.core.liveness import LinkQuality
from server.link.core.state import (
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
from server.link.link import Link
from server.link.plugins.component_metadata import MetadataError
from server.link.plugins.manual_control import Sticks
from server.link.plugins.param_metadata import ParamInfo
from server.link.plugins.params import ParamError, ParamUnknown
from server.link.vehicle import Vehicle

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
    "MetadataError",
    "OriginState",
    "ParamError",
    "ParamInfo",
    "ParamUnknown",
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
