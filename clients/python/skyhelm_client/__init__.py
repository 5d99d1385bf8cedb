"""A typed Python client for the SkyHelm API: :class:`SkyHelm` (blocking) and
:class:`AsyncSkyHelm` (asyncio), with the same calls. Setpoints are the link's own setpoint
kinds (``PositionNed(north_m=10, east_m=0, down_m=-5)``; every kind in
``server.client.setpoints``, which is ``server.link.setpoint_kinds``), so their fields, units
and limits have one definition. Only the package's runtime dependencies are needed (httpx,
websockets).

    from server.client import PositionNed, SkyHelm

    with SkyHelm("http://127.0.0.1:8000/?token=...") as sky:
        sky.acquire()
        sky.arm()
        sky.takeoff(altitude_m=5)
        sky.wait_until(lambda s: s.altitude_m > 4.5, timeout_s=60)
        sky.offboard_start(PositionNed(north_m=0, east_m=0, down_m=-5))
"""

from server.client.aio import AsyncSkyHelm
from server.client.errors import (
    Forbidden,
    InvalidInput,
    NoAnswer,
    NoLease,
    NotFound,
    Refused,
    SkyHelmError,
    Unauthorized,
    Unavailable,
    WaitTimedOut,
)
from server.client.models import CommandResult, Lease, Message, Ned, State
from server.client.sync import SkyHelm
from server.link import setpoint_kinds as setpoints
from server.link.setpoint_kinds import PositionNed, SetpointKind, VelocityBody, VelocityNed

__all__ = [
    "AsyncSkyHelm",
    "CommandResult",
    "Forbidden",
    "InvalidInput",
    "Lease",
    "Message",
    "Ned",
    "NoAnswer",
    "NoLease",
    "NotFound",
    "PositionNed",
    "Refused",
    "SetpointKind",
    "SkyHelm",
    "SkyHelmError",
    "State",
    "Unauthorized",
    "Unavailable",
    "VelocityBody",
    "VelocityNed",
    "WaitTimedOut",
    "setpoints",
]
