"""A typed Python client for the SkyHelm API: :class:`SkyHelm` (blocking) and
:class:`AsyncSkyHelm` (asyncio), with the same calls. Setpoints are the wire's setpoint
kinds (``PositionNed(north_m=10, east_m=0, down_m=-5)``; every kind in
``skyhelm_client.setpoints``, which is ``skyhelm_wire.setpoint_kinds``), and answers are
parsed with the wire's models, so fields, units and limits have one definition. It needs
httpx, websockets and the wire package (pydantic), nothing of the server.

    from skyhelm_client import PositionNed, SkyHelm

    with SkyHelm("http://127.0.0.1:8000/?token=...") as sky:
        sky.acquire()
        sky.arm()
        sky.takeoff(altitude_m=5)
        sky.wait_until(lambda s: s.altitude_m > 4.5, timeout_s=60)
        sky.offboard_start(PositionNed(north_m=0, east_m=0, down_m=-5))
"""

from skyhelm_client.aio import AsyncSkyHelm
from skyhelm_client.errors import (
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
from skyhelm_client.models import Answer, CommandResult, Lease, Message, Ned, ParamValues, State
from skyhelm_client.sync import SkyHelm
from skyhelm_wire import setpoint_kinds as setpoints
from skyhelm_wire.setpoint_kinds import PositionNed, SetpointKind, VelocityBody, VelocityNed

__all__ = [
    "Answer",
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
    "ParamValues",
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
