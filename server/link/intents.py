"""Intents: what a pilot or a script means ("stop here", "fly at this speed", "go there"),
decided here once so that the page, REST scripts and WebSocket clients get the same
behaviour and the same checks.

Brake then hold: a position setpoint where the vehicle *is* when the pilot lets go makes it
fly back to that point against its own momentum. So the stream first carries a zero
velocity, and once the vehicle has slowed down (or after a bound), a position hold where
it stopped. Anything else set meanwhile wins: the hold is sent only if the zero velocity
is still the setpoint being streamed.
"""

from __future__ import annotations

import asyncio
import math
import weakref

from server.link.aio import cancel_and_wait
from server.link.setpoint_checks import SetpointRejected
from server.link.setpoints import SentSetpoint, VelocityNed
from server.link.vehicle import Vehicle

HOLD_STOPPED_M_S = 0.3  # below this speed the vehicle counts as stopped
HOLD_BRAKE_TIMEOUT_S = 5.0  # hold wherever it is after this long, slow or not

# one pending brake-to-hold switch per vehicle; a new brake replaces the old one
_pending: weakref.WeakKeyDictionary[Vehicle, asyncio.Task[None]] = weakref.WeakKeyDictionary()


def speed_m_s(vehicle: Vehicle) -> float | None:
    """The vehicle's 3D speed from its NED velocity, or None before it reported one."""
    v = vehicle.telemetry.velocity_ned
    if v is None:
        return None
    return math.hypot(v.north_m_s, v.east_m_s, v.down_m_s)


async def brake_then_hold(vehicle: Vehicle) -> SentSetpoint:
    """Stream a zero velocity now, then a position hold where the vehicle stops.

    Returns at once with the zero velocity sent; the switch to the hold happens in the
    background and is published as an ``intent`` event. Skips the envelope (a vehicle
    outside it must still be able to stop). Raises SetpointRejected without a position.
    """
    await cancel_and_wait(_pending.pop(vehicle, None))
    try:
        sent = await vehicle.set_setpoint(VelocityNed(0.0, 0.0, 0.0))
    except SetpointRejected as exc:
        if exc.field != "type":
            raise
        # a fixed wing takes no velocity setpoint: hold where it is at once
        return await _hold(vehicle)
    brake = vehicle.offboard.setpoint
    vehicle.publish_event("intent", {"intent": "brake", "phase": "braking"})
    _pending[vehicle] = asyncio.get_running_loop().create_task(_hold_when_stopped(vehicle, brake))
    return sent


async def _hold_when_stopped(vehicle: Vehicle, brake: object) -> None:
    def stopped() -> bool:
        speed = speed_m_s(vehicle)
        return speed is not None and speed <= HOLD_STOPPED_M_S

    await vehicle.wait_until(stopped, HOLD_BRAKE_TIMEOUT_S)
    if vehicle.offboard.setpoint is not brake:
        return  # another setpoint (or the end of the stream) came first: it wins
    try:
        await _hold(vehicle)
    except SetpointRejected as exc:  # no position to hold: keep the zero velocity
        vehicle.publish_event("intent", {"intent": "brake", "phase": "braking", "why": str(exc)})


async def _hold(vehicle: Vehicle) -> SentSetpoint:
    sent = await vehicle.hold_position_setpoint()
    vehicle.publish_event("intent", {"intent": "brake", "phase": "holding"})
    return sent
