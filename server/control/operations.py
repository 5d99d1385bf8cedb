"""Vehicle commands and intents, each the operation of a call of the wire's table
(``skyhelm_wire.calls``) by its name, taking the call's body: the REST routes, the WebSocket
control session and the fleet edge run the same tables, so all refuse and answer alike. An
operation is registered with ``@command("name")`` or ``@intent("name")``; its body is its
second parameter's annotation, held to the table's at import. Refusals are the link's and
the control core's own exceptions (``refusals``), which each adapter answers in its
transport's terms. The checks (the envelope for take-off, reposition, setpoints and
intents) are the link's own, made where it sends them."""

from __future__ import annotations

import inspect
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, TypeVar, get_type_hints

from pydantic import BaseModel

from server.control.deadman import Deadman
from server.control.refusals import InvalidInput
from server.link import CommandOutcome, CommandResult, SentSetpoint, Vehicle, intents
from server.link.intents import IntentResult
from skyhelm_wire import commands as schemas
from skyhelm_wire.calls import COMMAND_CALLS
from skyhelm_wire.commands import CommandResultOut
from skyhelm_wire.intents import (
    BrakeBody,
    GeoTargetOut,
    GotoIntentBody,
    IntentOut,
    OffsetIntentBody,
    VelocityIntentBody,
)
from skyhelm_wire.setpoints import SentSetpointOut, setpoint_body

_F = TypeVar("_F", bound=Callable[..., Any])


class NoBody(BaseModel):
    pass


@dataclass(frozen=True)
class Operation:
    """A command: its body and its function, whose name and docstring its REST route takes
    (they name and describe it in OpenAPI)."""

    body: type[BaseModel]
    run: Callable[[Vehicle, Any], Awaitable[CommandResult]]


@dataclass(frozen=True)
class Intent:
    """An intent: its body and its function, whose name and docstring its REST route takes
    (they name and describe it in OpenAPI)."""

    body: type[BaseModel]
    run: Callable[[Vehicle, Any], Awaitable[IntentResult]]


# the operations by the name of their call, as @command and @intent register them
OPERATIONS: dict[str, Operation] = {}
INTENTS: dict[str, Intent] = {}


def _body_of(run: Callable[..., Any]) -> type[BaseModel]:
    """The body an operation takes: the annotation of its second parameter."""
    second = list(inspect.signature(run).parameters)[1]
    body: type[BaseModel] = get_type_hints(run)[second]
    return body


def command(name: str) -> Callable[[_F], _F]:
    """Register the decorated function as the command of the call ``name``."""

    def register(run: _F) -> _F:
        OPERATIONS[name] = Operation(_body_of(run), run)
        return run

    return register


def intent(name: str) -> Callable[[_F], _F]:
    """Register the decorated function as the intent of the call ``name``."""

    def register(run: _F) -> _F:
        INTENTS[name] = Intent(_body_of(run), run)
        return run

    return register


@command("arm")
async def arm(vehicle: Vehicle, body: schemas.ArmBody) -> CommandResult:
    return await vehicle.arm(force=body.force)


@command("disarm")
async def disarm(vehicle: Vehicle, body: schemas.ArmBody) -> CommandResult:
    """Without force PX4 refuses unless landed ("Disarming denied: not landed")."""
    return await vehicle.disarm(force=body.force)


@command("takeoff")
async def takeoff(vehicle: Vehicle, body: schemas.TakeoffBody) -> CommandResult:
    """Climb to altitude_m above home (default: the vehicle's MIS_TAKEOFF_ALT); above the
    envelope's max_alt_rel_m: 422."""
    return await vehicle.takeoff(body.altitude_m)


@command("land")
async def land(vehicle: Vehicle, _: NoBody) -> CommandResult:
    return await vehicle.land()


@command("rtl")
async def rtl(vehicle: Vehicle, _: NoBody) -> CommandResult:
    return await vehicle.return_to_launch()


@command("hold")
async def hold(vehicle: Vehicle, _: NoBody) -> CommandResult:
    return await vehicle.hold()


@command("mode")
async def set_mode(vehicle: Vehicle, body: schemas.ModeBody) -> CommandResult:
    """Resolves when the vehicle reports the mode (or says why not)."""
    return await vehicle.set_mode(body.mode)


@command("reposition")
async def reposition(vehicle: Vehicle, body: schemas.RepositionBody) -> CommandResult:
    """MAV_CMD_DO_REPOSITION: fly there and hold (ends OFFBOARD). Outside the envelope: 422
    naming the field and the limit. The goto intent picks this or a setpoint by mode."""
    return await vehicle.reposition(
        body.lat_deg,
        body.lon_deg,
        alt_amsl_m=body.alt_amsl_m,
        alt_rel_m=body.alt_rel_m,
        ground_speed_m_s=body.ground_speed_m_s,
        yaw_deg=body.yaw_deg,
        loiter_radius_m=body.loiter_radius_m,
    )


@command("vtol_transition")
async def vtol_transition(vehicle: Vehicle, body: schemas.VtolTransitionBody) -> CommandResult:
    """With wait, resolves when EXTENDED_SYS_STATE shows the new VTOL state."""
    return await vehicle.vtol_transition(
        body.to == "fixed_wing", immediate=body.immediate, wait=body.wait
    )


@command("origin")
async def set_origin(vehicle: Vehicle, body: schemas.OriginBody) -> CommandResult:
    """SET_GPS_GLOBAL_ORIGIN, confirmed by the GPS_GLOBAL_ORIGIN the vehicle sends back."""
    return await vehicle.set_gps_origin(body.lat_deg, body.lon_deg, body.alt_amsl_m)


@command("home")
async def set_home(vehicle: Vehicle, body: schemas.HomeBody) -> CommandResult:
    """MAV_CMD_DO_SET_HOME at the given point, or at the current position without a body."""
    return await vehicle.set_home(body.lat_deg, body.lon_deg, body.alt_amsl_m)


@command("offboard_start")
async def offboard_start(vehicle: Vehicle, body: schemas.OffboardStartBody) -> CommandResult:
    """Stream the setpoint (default: hold here) and switch to OFFBOARD; resolves when the
    vehicle reports OFFBOARD."""
    setpoint = body.setpoint.to_link() if body.setpoint is not None else None
    return await vehicle.start_offboard(setpoint)


@command("offboard_stop")
async def offboard_stop(vehicle: Vehicle, body: schemas.OffboardStopBody) -> CommandResult:
    """Switch to then_mode, then stop streaming."""
    return await vehicle.stop_offboard(body.then_mode)




async def run_command(name: str, vehicle: Vehicle, body: BaseModel | None) -> CommandResult:
    """Run the operation ``name`` with its body (None: the body's defaults)."""
    operation = OPERATIONS[name]
    return await operation.run(vehicle, body if body is not None else operation.body())


# -- intents ------------------------------------------------------------------------------


@intent("brake")
async def brake(vehicle: Vehicle, _: BrakeBody) -> IntentResult:
    """Stop and hold where the vehicle stops. Streaming setpoints: a zero velocity, then a
    position hold once it is slow (events `intent` braking / holding). Otherwise HOLD mode,
    in which PX4 brakes and holds by itself."""
    return await intents.brake(vehicle)


@intent("velocity")
async def velocity(vehicle: Vehicle, body: VelocityIntentBody) -> IntentResult:
    """Fly at a velocity (body: forward/right, ned: north/east; up_m_s; yaw_rate_deg_s),
    streamed as an offboard setpoint. Live unless `live` is false: without a new call within
    the deadman timeout the vehicle brakes and holds. With hold_altitude the altitude of the
    first such call is held instead of a vertical speed."""
    x_m_s, y_m_s = body.xy_m_s()
    return await intents.velocity(
        vehicle,
        frame=body.frame,
        x_m_s=x_m_s,
        y_m_s=y_m_s,
        up_m_s=body.up_m_s,
        yaw_rate_deg_s=body.yaw_rate_deg_s,
        hold_altitude=body.hold_altitude,
    )


@intent("offset")
async def offset(vehicle: Vehicle, body: OffsetIntentBody) -> IntentResult:
    """Go by north_m/east_m/up_m from where the vehicle is (the point computed on WGS-84).
    In OFFBOARD as a position setpoint; in any other mode as MAV_CMD_DO_REPOSITION."""
    return await intents.offset(
        vehicle, north_m=body.north_m, east_m=body.east_m, up_m=body.up_m, yaw_deg=body.yaw_deg
    )


@intent("goto")
async def goto(vehicle: Vehicle, body: GotoIntentBody) -> IntentResult:
    """Go to lat_deg/lon_deg at alt_rel_m above home (default: the current altitude). In
    OFFBOARD as a global position setpoint; in any other mode as MAV_CMD_DO_REPOSITION."""
    return await intents.goto(
        vehicle,
        lat_deg=body.lat_deg,
        lon_deg=body.lon_deg,
        alt_rel_m=body.alt_rel_m,
        yaw_deg=body.yaw_deg,
    )


def held_to_the_table() -> None:
    """Every command and intent of the wire's table has an operation taking its body (a
    body-less call: one with no fields), and no operation is outside the table."""
    wanted = {call.name: call for call in COMMAND_CALLS}
    found: dict[str, Operation | Intent] = {**OPERATIONS, **INTENTS}
    if set(found) != set(wanted):
        raise ImportError(f"calls without an operation or operations without a call: "
                          f"{sorted(set(found) ^ set(wanted))}")  # fmt: skip
    for name, operation in found.items():
        call = wanted[name]
        is_intent = call.answer is IntentOut
        if is_intent != (name in INTENTS):
            kind = "an intent" if is_intent else "a command"
            raise ImportError(f"{name} is {kind} in the table, not registered as one")
        if call.body is not operation.body and (call.body, operation.body.model_fields) != (
            None, {}
        ):
            raise ImportError(f"{name} takes {operation.body.__name__}; the table: {call.body}")


held_to_the_table()
INTENT_NAMES = frozenset(INTENTS)


def command_out(result: CommandResult) -> CommandResultOut:
    """What a command came to, as every adapter answers it."""
    return CommandResultOut(
        command=result.command,
        result=result.outcome.name,  # type: ignore[arg-type]
        result_code=result.result_code,
        elapsed_ms=round(result.elapsed_ms, 1),
        reason=result.reason,
    )


@dataclass(frozen=True)
class IntentAnswer:
    """An intent's answer: the outcome of the command it sent (None: it streamed a
    setpoint), its JSON body, and whether the deadman must watch it (a live velocity) or
    stop watching (anything else)."""

    outcome: CommandOutcome | None
    body: dict[str, Any]
    live: bool


def sent_out(sent: SentSetpoint) -> SentSetpointOut:
    """What went on the wire, as the setpoint routes and the control socket answer it."""
    return SentSetpointOut(
        setpoint=setpoint_body(sent.setpoint),
        message=sent.message,
        frame=sent.frame,
        type_mask=sent.type_mask,
    )


def intent_out(result: IntentResult, *, live: bool) -> IntentOut:
    target = result.target
    return IntentOut(
        intent=result.intent,
        via=result.via,
        setpoint=sent_out(result.sent) if result.sent is not None else None,
        command=command_out(result.command) if result.command is not None else None,
        target=GeoTargetOut(
            lat_deg=target.lat_deg, lon_deg=target.lon_deg, alt_rel_m=target.alt_rel_m
        )
        if target is not None
        else None,
        live=live,
    )


async def run_intent(name: str, vehicle: Vehicle, args: object) -> IntentAnswer:
    """Validate ``args`` (a body model or its JSON form) and run the intent. Bad input,
    envelope refusals and missing positions raise (``InvalidInput``, ``SetpointRejected``)."""
    intent = INTENTS.get(name)
    if intent is None:
        raise InvalidInput(f"unknown intent; one of {', '.join(INTENTS)}", field="name")
    body = args if isinstance(args, intent.body) else intent.body.model_validate(args or {})
    result = await intent.run(vehicle, body)
    live = bool(getattr(body, "live", False)) and result.sent is not None
    outcome = None if result.command is None else result.command.outcome
    return IntentAnswer(outcome, intent_out(result, live=live).model_dump(mode="json"), live)


async def answer_intent(
    deadman: Deadman, vehicle: Vehicle, name: str, args: object
) -> IntentAnswer:
    """Run an intent and tell the deadman whether the input is live now."""
    answer = await run_intent(name, vehicle, args)
    deadman.watch_live(vehicle.sysid, live=answer.live)
    return answer
