"""NaN and ±infinity in any field of any request body are a 422 naming the field, never a
500 and never passed on to the vehicle.

Python's JSON parser takes the NaN, Infinity and -Infinity tokens, so they reach the body
models. Every body and field is read from /openapi.json, so a new body is covered the
moment it is served; hypothesis fills the other fields with valid values."""

from __future__ import annotations

import functools
import json
import math
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass
from typing import Any

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from server.app import create_app
from tests.api.conftest import Api, api_for, make_settings, sim_cluster

NON_FINITE = (math.nan, math.inf, -math.inf)
PATH_VALUES = {"vehicle_id": "1", "name": "MPC_XY_CRUISE", "request_id": "no-such-request"}
Schema = dict[str, Any]


@dataclass(frozen=True)
class Case:
    method: str
    path: str
    field: tuple[str, ...]
    value: float
    body: Any

    def __str__(self) -> str:
        return f"{self.method.upper()} {self.path} {'.'.join(self.field)}={self.value}"


def _spec() -> Schema:
    spec: Schema = create_app(make_settings(None)).openapi()
    return spec


def _resolved(spec: Schema, schema: Schema) -> Schema:
    while "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[1]
        schema = spec["components"]["schemas"][name]
    return schema


def _non_null(spec: Schema, schema: Schema) -> list[Schema]:
    """The members of a union, nested unions flattened, that are not null (the schema
    itself when not a union)."""
    schema = _resolved(spec, schema)
    members = schema.get("anyOf") or schema.get("oneOf")
    if members is None:
        return [] if schema.get("type") == "null" else [schema]
    return [flat for m in members for flat in _non_null(spec, m)]


def _fields(
    spec: Schema, schema: Schema, prefix: tuple[str, ...] = ()
) -> Iterator[tuple[str, ...]]:
    """Every field of an object body, nested objects' fields too."""
    for name, field_schema in schema.get("properties", {}).items():
        yield (*prefix, name)
        for member in _non_null(spec, field_schema):
            if member.get("type") == "object":
                yield from _fields(spec, member, (*prefix, name))


def _valid(spec: Schema, schema: Schema) -> st.SearchStrategy[Any]:
    """Values the schema accepts (within its bounds; finite)."""
    schema = _non_null(spec, schema)[0]
    if "const" in schema:
        return st.just(schema["const"])
    if "enum" in schema:
        return st.sampled_from(schema["enum"])
    kind = schema.get("type")
    if kind in ("number", "integer"):
        low = schema.get("minimum", schema.get("exclusiveMinimum", -1e3))
        high = schema.get("maximum", schema.get("exclusiveMaximum", 1e3))
        if kind == "integer":
            return st.integers(int(low) + 1, max(int(low) + 1, int(high) - 1))
        return st.floats(low, high, allow_nan=False, allow_infinity=False,
                         exclude_min="exclusiveMinimum" in schema,
                         exclude_max="exclusiveMaximum" in schema)  # fmt: skip
    if kind == "boolean":
        return st.booleans()
    if kind == "string":
        return st.text("abcdefghijklmnopqrstuvwxyz", min_size=1, max_size=12)
    if kind == "array":
        return st.just([])
    if kind == "object":
        required = schema.get("required", [])
        props = schema.get("properties", {})
        return st.fixed_dictionaries({name: _valid(spec, props[name]) for name in required})
    return st.none()


def _with(
    spec: Schema, schema: Schema, field: tuple[str, ...], value: float
) -> st.SearchStrategy[Any]:
    """A valid object for ``schema`` with ``value`` put at ``field``."""
    name, rest = field[0], field[1:]
    inner: st.SearchStrategy[Any] = st.just(value)
    if rest:
        members = _non_null(spec, schema["properties"][name])
        nested = next(m for m in members if rest[0] in m.get("properties", {}))
        inner = _with(spec, nested, rest, value)
    return st.tuples(_valid(spec, schema), inner).map(lambda pair: {**pair[0], name: pair[1]})


def _drawn(strategy: st.SearchStrategy[Any]) -> Any:
    drawn: list[Any] = []

    @settings(max_examples=1, derandomize=True, database=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck), deadline=None)  # fmt: skip
    @given(strategy)
    def collect(value: Any) -> None:
        drawn.append(value)

    collect()
    return drawn[0]


@functools.cache
def cases() -> list[Case]:
    """Every (body, field, non-finite value), drawn when a test first asks: at collection,
    every worker of the suite would draw them all (a third of its collection's time)."""
    spec = _spec()
    found = []
    for path, operations in spec["paths"].items():
        for method, operation in operations.items():
            body = operation.get("requestBody")
            if body is None:
                continue
            for variant in _non_null(spec, body["content"]["application/json"]["schema"]):
                for field in dict.fromkeys(_fields(spec, variant)):
                    for value in NON_FINITE:
                        example = _drawn(_with(spec, variant, field, value))
                        found.append(Case(method, path, field, value, example))
    return found


def test_every_body_of_the_api_is_covered() -> None:
    covered = {(c.method, c.path) for c in cases()}
    assert ("put", "/api/v1/vehicles/{vehicle_id}/setpoint") in covered
    assert ("post", "/api/v1/vehicles/{vehicle_id}/control") in covered
    assert ("post", "/api/v1/vehicles/{vehicle_id}/origin") in covered
    assert ("put", "/api/v1/vehicles/{vehicle_id}/params/{name}") in covered
    setpoint_fields = {c.field for c in cases() if c.path.endswith("/setpoint")}
    assert ("north_m",) in setpoint_fields
    assert ("yaw_rate_deg_s",) in setpoint_fields or len(setpoint_fields) > 10


@pytest.fixture
async def live_api() -> AsyncIterator[Api]:
    # hundreds of bodies in a burst from one token: the per-token rate limit is not what
    # this test is about (tests/api/test_security_limits.py pins it)
    unlimited = {"control_rate_per_s": 1e5, "control_burst": 100000}
    async with sim_cluster("quad") as sim, api_for(sim, lease_ttl_s=60.0, **unlimited) as api:
        await api.wait_ready()
        await api.take_control()
        yield api


def _is_subsequence(part: list[str], whole: list[str]) -> bool:
    rest = iter(whole)
    return all(name in rest for name in part)


def _names_the_field(detail: Any, field: tuple[str, ...]) -> bool:
    """The 422 names the field: an ApiError's ``field``, or a pydantic error's ``loc``, where
    a union adds its member (["body", "setpoint", "position_ned", "north_m"])."""
    if isinstance(detail, dict):
        return _is_subsequence(list(field), str(detail.get("field", "")).split("."))
    for error in detail:
        loc = [str(part) for part in error["loc"]]
        if _is_subsequence(list(field), loc):
            return True
        # a bad discriminator is reported at the union, and its message names the tag
        at_union = len(field) == 1 or loc[-len(field) + 1 :] == list(field[:-1])
        if error.get("type") == "union_tag_invalid" and field[-1] == "type" and at_union:
            return True
    return False


async def test_non_finite_numbers_in_every_field_are_422_naming_the_field(
    live_api: Api,
) -> None:
    api = live_api
    failures = []
    for case in cases():
        url = case.path
        for name, value in PATH_VALUES.items():
            url = url.replace("{" + name + "}", value)
        response = await api.client.request(
            case.method, url, content=json.dumps(case.body),
            headers={**api.lease_headers, "Content-Type": "application/json"},
        )  # fmt: skip
        if response.status_code == 423:  # the lease lapsed between cases: take it again
            await api.take_control()
            response = await api.client.request(
                case.method, url, content=json.dumps(case.body),
                headers={**api.lease_headers, "Content-Type": "application/json"},
            )  # fmt: skip
        if response.status_code != 422:
            failures.append(f"{case}: {response.status_code} {response.text[:200]}")
            continue
        if not _names_the_field(response.json()["detail"], case.field):
            failures.append(f"{case}: 422 without the field: {response.text[:300]}")
    assert not failures, "\n".join(failures)


WS_MESSAGES = [
    ({"type": "setpoint", "setpoint": {"type": "position_ned", "north_m": "X", "east_m": 0.0,
                                       "down_m": -3.0}}, "north_m"),
    ({"type": "command", "name": "takeoff", "args": {"altitude_m": "X"}}, "altitude_m"),
    ({"type": "command", "name": "origin",
      "args": {"lat_deg": 47.0, "lon_deg": "X", "alt_amsl_m": 400.0}}, "lon_deg"),
]  # fmt: skip


@pytest.mark.parametrize("token", ["NaN", "Infinity", "-Infinity"])
async def test_non_finite_numbers_in_control_socket_messages_are_422_naming_the_field(
    token: str,
) -> None:
    from websockets.asyncio.client import connect

    from tests.api.test_ws import receive, receive_until, served

    async with served() as quad, connect(quad.url("control", vehicle=1)) as ws:
        assert (await receive(ws))["type"] == "lease"
        for request_id, (message, field) in enumerate(WS_MESSAGES):
            text = json.dumps({**message, "id": request_id}).replace('"X"', token)
            await ws.send(text)
            answer = await receive_until(ws, {"id": request_id})
            assert answer["status"] == 422, answer
            assert field in str(answer["body"]["detail"]["field"]), answer
        # the socket still answers
        await ws.send(json.dumps({"type": "heartbeat", "id": 99}))
        assert (await receive_until(ws, {"id": 99}))["status"] == 200


def test_non_finite_field_names_the_first_nan_or_infinity_in_a_message() -> None:
    from server.http.errors import ApiError, non_finite_field, refuse_non_finite

    message = json.loads('{"id": 1, "setpoint": {"north_m": 1.0, "east_m": [0, -Infinity]}}')
    assert non_finite_field(message) == "setpoint.east_m.1"
    assert non_finite_field(json.loads('{"id": NaN}')) == "id"
    assert non_finite_field({"id": 1, "args": {"force": True}}) is None
    with pytest.raises(ApiError) as refused:
        refuse_non_finite(json.loads('{"type": "heartbeat", "id": Infinity}'))
    assert (refused.value.status_code, refused.value.detail["field"]) == (422, "id")


def test_every_request_body_model_derives_from_the_strict_body() -> None:
    import typing

    from fastapi.routing import APIRoute
    from pydantic import BaseModel

    from server.http.schemas import StrictBody

    def models(hint: Any) -> Iterator[type[BaseModel]]:
        if isinstance(hint, type) and issubclass(hint, BaseModel):
            yield hint
        for arg in typing.get_args(hint):
            yield from models(arg)

    def routes(items: list[Any]) -> Iterator[APIRoute]:
        for item in items:
            if isinstance(item, APIRoute):
                yield item
            included = getattr(item, "original_router", None)  # an included router
            yield from routes(getattr(included or item, "routes", []))

    app = create_app(make_settings(None))
    bodies = {
        model: route.path
        for route in routes(app.routes)
        if route.body_field is not None
        for model in models(route.body_field.field_info.annotation)
    }
    assert len(bodies) > 10
    loose = [f"{path}: {model.__name__}" for model, path in bodies.items()
             if not issubclass(model, StrictBody)]  # fmt: skip
    assert not loose
