"""The calls under ``/api/v1/vehicles/{vehicle_id}``, from the wire's table
(``skyhelm_wire.calls``: method, path, who may make it, the body, query and path models),
each paired here with the function its REST route runs (lease_ops, vehicle_ops,
operations). The fleet edge runs a call that came over Zenoh through this table
(server/fleet/edge_calls.py); each REST route calls the same function, so both answer
alike. ``tests/fleet/test_edge_parity.py`` holds the two side by side."""

from __future__ import annotations

import asyncio
import enum
import json
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any

from pydantic import BaseModel, Field, TypeAdapter, ValidationError

from server.control import lease_ops, operations, vehicle_ops
from server.control.publishers import StatePublishers
from server.http.context import ApiContext
from server.http.errors import command_answer, command_status
from server.link import Vehicle
from skyhelm_wire.calls import VEHICLE_CALLS as WIRE_CALLS
from skyhelm_wire.calls import CallSpec
from skyhelm_wire.control import ControlBody, RenewBody


class Access(enum.Enum):
    """What a call asks of its caller, checked in REST's order (the wire's ``Access``)."""

    READ = "read"  # any token; the vehicle known
    CONNECTED = "connected"  # any token; the vehicle known and connected
    PILOT = "pilot"  # the pilot token; the vehicle known (the lease calls)
    CONTROL = "control"  # the pilot token, the vehicle, its lease (X-Lease-Id), connected


@dataclass
class Reply:
    """An answer: its status, its JSON body (b"": none) and the headers a caller acts on."""

    status: int
    body: bytes = b""
    headers: dict[str, str] = field(default_factory=dict)


def model_reply(model: BaseModel, status: int = 200) -> Reply:
    return Reply(status, model.model_dump_json(by_alias=True).encode())


@dataclass
class CallArgs:
    """One call's checked inputs."""

    context: ApiContext
    publishers: StatePublishers
    vehicle: Vehicle
    lease_id: str | None
    client: lease_ops.Client | None
    body: Any = None
    query: dict[str, Any] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)


Run = Callable[[CallArgs], Awaitable[Reply]]


@dataclass(frozen=True)
class Param:
    """A query or path parameter: its type as the route declares it, and its default."""

    name: str
    adapter: TypeAdapter[Any]
    default: Any = None


@dataclass(frozen=True)
class VehicleCall:
    method: str
    path: str  # under the vehicle, "" for the vehicle itself; {name} for a path parameter
    access: Access
    run: Run
    body: TypeAdapter[Any] | None = None  # None: the call takes no body
    body_required: bool = False
    query: tuple[Param, ...] = ()
    params: tuple[Param, ...] = ()


# -- the calls --------------------------------------------------------------------------------


async def _state(args: CallArgs) -> Reply:
    return Reply(200, vehicle_ops.state_json(args.publishers, args.vehicle))


async def _stream(args: CallArgs) -> Reply:
    return model_reply(vehicle_ops.stream_out(args.vehicle))


async def _never() -> None:
    # a Zenoh querier cannot be seen to leave: the ask ends by the holder's answer or timeout
    await asyncio.Event().wait()


async def _acquire(args: CallArgs) -> Reply:
    context = args.context
    lease = await lease_ops.acquire(
        context.leases, args.vehicle, args.body or ControlBody(), args.lease_id,
        pilot=context.pilot_name, client=args.client,
        ask_s=context.settings.takeover_ask_s, gone=_never,
    )  # fmt: skip
    return model_reply(lease)


async def _renew(args: CallArgs) -> Reply:
    context = args.context
    lease = lease_ops.renew(
        context.leases, args.vehicle, args.body or RenewBody(), args.lease_id,
        pilot=context.pilot_name,
    )
    return model_reply(lease)


async def _status(args: CallArgs) -> Reply:
    return model_reply(lease_ops.status(args.context.leases, args.vehicle.sysid))


async def _release(args: CallArgs) -> Reply:
    lease_ops.release(args.context.leases, args.vehicle, args.lease_id)
    return Reply(204)


async def _answer_takeover(args: CallArgs) -> Reply:
    answer = lease_ops.answer_takeover(
        args.context.leases, args.vehicle, args.lease_id, args.params["request_id"], args.body
    )
    return model_reply(answer)


async def _setpoint(args: CallArgs) -> Reply:
    sent = await vehicle_ops.put_setpoint(
        args.context.deadman, args.vehicle, args.body, live=args.query["live"]
    )
    return model_reply(sent)


async def _get_sticks(args: CallArgs) -> Reply:
    return model_reply(vehicle_ops.sticks_out(args.vehicle))


async def _put_sticks(args: CallArgs) -> Reply:
    return model_reply(vehicle_ops.fly_sticks(args.context.deadman, args.vehicle, args.body))


async def _delete_sticks(args: CallArgs) -> Reply:
    return model_reply(vehicle_ops.stop_sticks(args.context.deadman, args.vehicle))


async def _get_params(args: CallArgs) -> Reply:
    return model_reply(await vehicle_ops.get_params(args.vehicle, args.query["names"]))


async def _get_param_metadata(args: CallArgs) -> Reply:
    return model_reply(await vehicle_ops.get_param_metadata(args.vehicle))


async def _get_param(args: CallArgs) -> Reply:
    return model_reply(await vehicle_ops.get_param(args.vehicle, args.params["name"]))


async def _set_param(args: CallArgs) -> Reply:
    return model_reply(
        await vehicle_ops.set_param(args.vehicle, args.params["name"], args.body)
    )


def _command(name: str) -> Run:
    async def run(args: CallArgs) -> Reply:
        result = await operations.run_command(name, args.vehicle, args.body)
        status, body = command_answer(result)
        return Reply(status, _json(body))

    return run


def _intent(name: str) -> Run:
    async def run(args: CallArgs) -> Reply:
        answer = await operations.answer_intent(
            args.context.deadman, args.vehicle, name, args.body
        )
        return Reply(command_status(answer.outcome), _json(answer.body))

    return run


def _json(body: Any) -> bytes:
    return json.dumps(body, allow_nan=False).encode()


# the function each call of the wire's table runs, by the call's name
_RUNS: dict[str, Run] = {
    "state": _state, "stream": _stream, "control_status": _status, "acquire": _acquire,
    "renew": _renew, "release": _release, "answer_takeover": _answer_takeover,
    "set_setpoint": _setpoint, "sticks": _get_sticks, "fly_sticks": _put_sticks,
    "stop_sticks": _delete_sticks, "params": _get_params, "param_metadata": _get_param_metadata,
    "param": _get_param,
    "set_param": _set_param,
    **{name: _command(name) for name in operations.OPERATIONS},
    **{name: _intent(name) for name in operations.INTENTS},
}  # fmt: skip


def _params(model: type[BaseModel] | None) -> tuple[Param, ...]:
    """A query or path model's fields as the route declares each parameter."""
    if model is None:
        return ()
    return tuple(
        Param(name, TypeAdapter(field.rebuild_annotation()),
              None if field.is_required() else field.default)
        for name, field in model.model_fields.items()
    )  # fmt: skip


def _vehicle_call(spec: CallSpec) -> VehicleCall:
    return VehicleCall(
        spec.method, spec.path, Access(spec.access), _RUNS[spec.name],
        TypeAdapter(spec.body) if spec.body is not None else None, spec.body_required,
        _params(spec.query), _params(spec.path_params),
    )  # fmt: skip


if set(_RUNS) != {spec.name for spec in WIRE_CALLS}:
    raise ImportError(f"calls without a function or functions without a call: "
                      f"{sorted(set(_RUNS) ^ {spec.name for spec in WIRE_CALLS})}")  # fmt: skip
CALLS: tuple[VehicleCall, ...] = tuple(_vehicle_call(spec) for spec in WIRE_CALLS)
VEHICLE_ID = Param("vehicle_id", TypeAdapter(Annotated[int, Field(ge=0, le=255)]))


@dataclass(frozen=True)
class Match:
    call: VehicleCall | None  # None: the path is offered, not with this method (405)
    vehicle_id: str
    params: dict[str, str]


def _pattern(path: str) -> tuple[str, ...]:
    return tuple(path.split("/")) if path else ()


_BY_SHAPE: dict[tuple[str, ...], dict[str, VehicleCall]] = {}
for _call in CALLS:
    _BY_SHAPE.setdefault(_pattern(_call.path), {})[_call.method] = _call


def match(method: str, rest: str) -> Match | None:
    """The call for ``method`` and the path after ``/vehicles/`` (``1/control``); None when
    no call has that path."""
    vehicle_id, _, under = rest.partition("/")
    segments = tuple(under.split("/")) if under else ()
    for shape, by_method in _BY_SHAPE.items():
        if len(shape) != len(segments):
            continue
        params: dict[str, str] = {}
        for part, segment in zip(shape, segments, strict=True):
            if part.startswith("{"):
                if not segment:
                    break
                params[part[1:-1]] = segment
            elif part != segment:
                break
        else:
            return Match(by_method.get(method), vehicle_id, params)
    return None


def validate(
    call: VehicleCall, body: Any, query: Mapping[str, str], params: Mapping[str, str]
) -> tuple[Any, dict[str, Any], dict[str, Any], list[dict[str, Any]]]:
    """The call's body, query and path values as FastAPI validates them for its route, and
    the errors it would answer 422 with (its format: type, loc, msg, input)."""
    errors: list[dict[str, Any]] = []
    path_values = {p.name: _value(p, params.get(p.name), ("path", p.name), errors)
                   for p in call.params}  # fmt: skip
    query_values = {p.name: _value(p, query.get(p.name), ("query", p.name), errors)
                    for p in call.query}  # fmt: skip
    value = None
    if call.body is not None:
        if body is None:
            if call.body_required:
                errors.append(missing(("body",)))
        else:
            value = validated(call.body, body, ("body",), errors)
    return value, query_values, path_values, errors


def _value(param: Param, raw: str | None, loc: tuple[str, ...], errors: list[Any]) -> Any:
    if raw is None:
        return param.default
    return validated(param.adapter, raw, loc, errors)


def validated(
    adapter: TypeAdapter[Any], raw: Any, loc: tuple[str, ...], errors: list[Any]
) -> Any:
    try:
        return adapter.validate_python(raw, from_attributes=True)
    except ValidationError as exc:
        errors.extend({**e, "loc": loc + tuple(e["loc"])} for e in exc.errors(include_url=False))
        return None


def missing(loc: tuple[str, ...]) -> dict[str, Any]:
    """FastAPI's error for a required input that is absent."""
    return {"type": "missing", "loc": loc, "msg": "Field required", "input": None}
