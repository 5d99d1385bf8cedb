"""Intents: what a pilot or a script means ("stop here", "fly at this speed", "go there"),
decided here once so that the page, REST scripts and WebSocket clients get the same
behaviour and the same checks.

How each is flown, as a ground station that knows PX4 would:

- brake: with a setpoint stream running, the stream brakes (below); otherwise HOLD mode,
  PX4's AUTO.LOITER, which brakes and holds by itself.
- velocity: always an offboard setpoint (it only means something as a stream); the altitude
  hold is a LOCAL_NED setpoint with the z position and the x/y velocity, which PX4 reads
  axis by axis.
- offset and goto: in OFFBOARD, a position setpoint, so the vehicle stays in the mode the
  pilot chose and the stream keeps its deadman; in any other mode, MAV_CMD_DO_REPOSITION,
  which PX4 flies in HOLD without a stream and which survives the client going away.
  Both are held to the envelope before anything is sent.

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
from dataclasses import dataclass
from typing import Literal

from server.link.codec.aio import cancel_and_wait
from server.link.codec.commands import CommandResult
from server.link.codec.envelope import GeoTarget, SetpointRejected, check_target
from server.link.codec.geo import geodetic_from_ned_m
from server.link.codec.setpoints import (
    MAV_FRAME_LOCAL_NED,
    POSITION_TARGET_TYPEMASK_AX_IGNORE,
    POSITION_TARGET_TYPEMASK_AY_IGNORE,
    POSITION_TARGET_TYPEMASK_AZ_IGNORE,
    POSITION_TARGET_TYPEMASK_VZ_IGNORE,
    POSITION_TARGET_TYPEMASK_X_IGNORE,
    POSITION_TARGET_TYPEMASK_Y_IGNORE,
    POSITION_TARGET_TYPEMASK_YAW_IGNORE,
    POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE,
    PositionGlobal,
    PositionNed,
    RawLocal,
    SentSetpoint,
    Setpoint,
    VelocityBody,
    VelocityNed,
)
from server.link.vehicle import Vehicle
from skyhelm_wire.intents import IntentName

HOLD_STOPPED_M_S = 0.3  # below this speed the vehicle counts as stopped
HOLD_BRAKE_TIMEOUT_S = 5.0  # hold wherever it is after this long, slow or not

# velocity x/y with a held altitude: x, y position, z velocity and acceleration unused
_ALTITUDE_HOLD_MASK = (
    POSITION_TARGET_TYPEMASK_X_IGNORE
    | POSITION_TARGET_TYPEMASK_Y_IGNORE
    | POSITION_TARGET_TYPEMASK_VZ_IGNORE
    | POSITION_TARGET_TYPEMASK_AX_IGNORE
    | POSITION_TARGET_TYPEMASK_AY_IGNORE
    | POSITION_TARGET_TYPEMASK_AZ_IGNORE
)
_YAW_BITS = POSITION_TARGET_TYPEMASK_YAW_IGNORE | POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE

Via = Literal["setpoint", "reposition", "hold_mode"]
VelocityFrame = Literal["body", "ned"]


@dataclass(frozen=True)
class IntentResult:
    """What an intent came to: the setpoint streamed or the command the vehicle answered,
    and for a move, where it goes."""

    intent: IntentName
    via: Via
    sent: SentSetpoint | None = None
    command: CommandResult | None = None
    target: GeoTarget | None = None

    @property
    def ok(self) -> bool:
        return self.command is None or self.command.ok


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
    await _cancel_brake(vehicle)
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
    if vehicle.offboard.setpoint is not brake or not vehicle.streamer_active:
        return  # another setpoint (or the end of the stream) came first: it wins
    try:
        await _hold(vehicle)
    except SetpointRejected as exc:  # no position to hold: keep the zero velocity
        vehicle.publish_event("intent", {"intent": "brake", "phase": "braking", "why": str(exc)})


async def _hold(vehicle: Vehicle) -> SentSetpoint:
    sent = await vehicle.hold_position_setpoint()
    vehicle.publish_event("intent", {"intent": "brake", "phase": "holding"})
    return sent


def in_offboard(vehicle: Vehicle) -> bool:
    """Whether the pilot flies OFFBOARD now (the mode intended, and the stream running)."""
    t = vehicle.telemetry
    intended = t.user_mode if t.user_mode is not None else t.mode
    return intended == "OFFBOARD" and vehicle.streamer_active


async def brake(vehicle: Vehicle) -> IntentResult:
    """Stop and stay where the vehicle stops: by the stream when one runs, else HOLD mode."""
    if vehicle.streamer_active:
        return IntentResult("brake", "setpoint", sent=await brake_then_hold(vehicle))
    await _cancel_brake(vehicle)
    return IntentResult("brake", "hold_mode", command=await vehicle.hold())


async def velocity(
    vehicle: Vehicle,
    *,
    frame: VelocityFrame,
    x_m_s: float,
    y_m_s: float,
    up_m_s: float = 0.0,
    yaw_rate_deg_s: float | None = None,
    hold_altitude: bool = False,
) -> IntentResult:
    """Fly at a velocity: (x, y) is (forward, right) in the body frame or (north, east).
    With hold_altitude the vertical is the altitude held since the first such call."""
    await _cancel_brake(vehicle)
    sp: Setpoint
    if hold_altitude:
        sp = _altitude_hold(vehicle, frame, x_m_s, y_m_s, yaw_rate_deg_s)
    elif frame == "body":
        sp = VelocityBody(x_m_s, y_m_s, -up_m_s, yaw_rate_deg_s)
    else:
        sp = VelocityNed(x_m_s, y_m_s, -up_m_s, yaw_rate_deg_s=yaw_rate_deg_s)
    return IntentResult("velocity", "setpoint", sent=await vehicle.set_setpoint(sp))


async def offset(
    vehicle: Vehicle,
    *,
    north_m: float,
    east_m: float,
    up_m: float = 0.0,
    yaw_deg: float | None = None,
) -> IntentResult:
    """Go by (north, east, up) metres from where the vehicle is."""
    here = vehicle.telemetry.global_position
    if here is None:
        raise SetpointRejected("no global position yet", field="north_m")
    lat_deg, lon_deg, _ = geodetic_from_ned_m(
        (north_m, east_m, -up_m), here.lat_deg, here.lon_deg, here.alt_amsl_m
    )
    target = GeoTarget(lat_deg, lon_deg, here.alt_rel_m + up_m)
    _check(vehicle, target, "offset", position_field="north_m", alt_field="up_m")
    local = vehicle.telemetry.position_ned
    if in_offboard(vehicle) and local is not None:
        # the offset in the vehicle's own local frame: no projection between here and there
        sp = PositionNed(local.north_m + north_m, local.east_m + east_m, local.down_m - up_m,
                         yaw_deg)  # fmt: skip
        return await _stream_move(vehicle, "offset", sp, target)
    return await _reposition(vehicle, "offset", target, yaw_deg)


async def goto(
    vehicle: Vehicle,
    *,
    lat_deg: float,
    lon_deg: float,
    alt_rel_m: float | None = None,
    yaw_deg: float | None = None,
) -> IntentResult:
    """Go to a point, at alt_rel_m above home (None: the current altitude)."""
    here = vehicle.telemetry.global_position
    if alt_rel_m is None and here is not None:
        alt_rel_m = here.alt_rel_m
    target = GeoTarget(lat_deg, lon_deg, alt_rel_m)
    _check(vehicle, target, "goto", position_field="lat_deg", alt_field="alt_rel_m")
    if in_offboard(vehicle):
        if alt_rel_m is None:
            raise SetpointRejected("no global position yet", field="alt_rel_m")
        sp = PositionGlobal(lat_deg, lon_deg, alt_rel_m, "relative", yaw_deg)
        return await _stream_move(vehicle, "goto", sp, target)
    return await _reposition(vehicle, "goto", target, yaw_deg)


def _check(
    vehicle: Vehicle, target: GeoTarget, what: str, *, position_field: str, alt_field: str
) -> None:
    check_target(
        vehicle.envelope,
        vehicle.telemetry.home,
        target,
        what=what,
        position_field=position_field,
        alt_field=alt_field,
    )


async def _stream_move(
    vehicle: Vehicle, intent: IntentName, sp: Setpoint, target: GeoTarget
) -> IntentResult:
    await _cancel_brake(vehicle)
    return IntentResult(intent, "setpoint", sent=await vehicle.set_setpoint(sp), target=target)


async def _reposition(
    vehicle: Vehicle, intent: IntentName, target: GeoTarget, yaw_deg: float | None
) -> IntentResult:
    await _cancel_brake(vehicle)
    result = await vehicle.reposition(
        target.lat_deg, target.lon_deg, alt_rel_m=target.alt_rel_m, yaw_deg=yaw_deg
    )
    return IntentResult(intent, "reposition", command=result, target=target)


def _altitude_hold(
    vehicle: Vehicle,
    frame: VelocityFrame,
    x_m_s: float,
    y_m_s: float,
    yaw_rate_deg_s: float | None,
) -> RawLocal:
    """Velocity x/y in LOCAL_NED at a fixed z: the z (and yaw) of the altitude hold being
    flown, or where the vehicle is now when this starts one."""
    t = vehicle.telemetry
    current = vehicle.offboard.setpoint
    if isinstance(current, RawLocal) and current.type_mask & ~_YAW_BITS == _ALTITUDE_HOLD_MASK:
        down_m, yaw_rad = current.z, current.yaw
    elif t.position_ned is not None and t.attitude is not None:
        down_m, yaw_rad = t.position_ned.down_m, math.radians(t.attitude.yaw_deg)
    else:
        raise SetpointRejected("no local position yet", field="hold_altitude")
    north_m_s, east_m_s = x_m_s, y_m_s
    if frame == "body":
        # turned into NED by the heading now; a live pilot's next update follows a turn
        heading = math.radians(t.attitude.yaw_deg) if t.attitude is not None else yaw_rad
        north_m_s = x_m_s * math.cos(heading) - y_m_s * math.sin(heading)
        east_m_s = x_m_s * math.sin(heading) + y_m_s * math.cos(heading)
    if yaw_rate_deg_s is None:
        yaw_bits, yaw_rate_rad_s = POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE, 0.0
    else:
        yaw_bits, yaw_rate_rad_s = POSITION_TARGET_TYPEMASK_YAW_IGNORE, math.radians(yaw_rate_deg_s)
    return RawLocal(
        frame=MAV_FRAME_LOCAL_NED,
        type_mask=_ALTITUDE_HOLD_MASK | yaw_bits,
        z=down_m,
        vx=north_m_s,
        vy=east_m_s,
        yaw=yaw_rad,
        yaw_rate=yaw_rate_rad_s,
    )


async def _cancel_brake(vehicle: Vehicle) -> None:
    """A new intent ends a brake still waiting to hold."""
    task = _pending.pop(vehicle, None)
    if task is not None and task is not asyncio.current_task():
        await cancel_and_wait(task)
