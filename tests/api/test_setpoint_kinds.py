"""Every setpoint kind the link defines reaches OpenAPI with its fields, units and limits, and a
body of that kind validates into the link's setpoint unchanged: adding a kind to
skyhelm_wire/setpoint_kinds.py is all the API needs."""

from __future__ import annotations

import math
import typing
from dataclasses import MISSING
from typing import Any

import pytest
from pydantic import TypeAdapter, ValidationError

from server.app import create_app
from server.http.schemas import SETPOINT_BODIES, SetpointBody
from skyhelm_wire.setpoint_kinds import (
    SETPOINT_KINDS,
    KindField,
    SetpointKind,
    describe,
    kind_fields,
)
from tests.api.conftest import make_settings

SETPOINT_PATH = "/api/v1/vehicles/{vehicle_id}/setpoint"
BODY = TypeAdapter(SetpointBody)
KINDS = list(SETPOINT_KINDS)
QUANTITY_FIELDS = [
    (name, field)
    for name, kind in SETPOINT_KINDS.items()
    for field in kind_fields(kind)
    if field.quantity is not None
]


@pytest.fixture(scope="module")
def openapi() -> dict[str, Any]:
    return create_app(make_settings(None, connect=["udpin:127.0.0.1:0"])).openapi()


def _mapping(openapi: dict[str, Any]) -> dict[str, str]:
    """The PUT /setpoint body's discriminator: kind -> schema reference (what the page reads)."""
    body = openapi["paths"][SETPOINT_PATH]["put"]["requestBody"]["content"]["application/json"]
    mapping: dict[str, str] = body["schema"]["discriminator"]["mapping"]
    return mapping


def _component(openapi: dict[str, Any], kind: str) -> dict[str, Any]:
    """The schema the PUT /setpoint discriminator names for a kind."""
    ref = _mapping(openapi)[kind]
    component: dict[str, Any] = openapi["components"]["schemas"][ref.rsplit("/", 1)[-1]]
    return component


def test_the_setpoint_body_takes_exactly_the_registered_kinds(openapi: dict[str, Any]) -> None:
    assert list(_mapping(openapi)) == KINDS


def _number_schema(prop: dict[str, Any]) -> dict[str, Any]:
    """A property's number schema, also inside `anyOf [number, null]`."""
    branches = [b for b in prop.get("anyOf", [prop]) if b.get("type") != "null"]
    assert len(branches) == 1, prop
    return branches[0]


def _inside(field: KindField) -> Any:
    """A value the field takes that is not its default."""
    if field.quantity is not None:
        value = min(max(1.25, field.quantity.ge), field.quantity.le)
        return int(value) if "int" in str(field.hint) else value
    return typing.get_args(field.hint)[-1]  # a Literal: its last choice


def _sample(kind: type[SetpointKind]) -> SetpointKind:
    return kind(**{field.name: _inside(field) for field in kind_fields(kind)})


@pytest.mark.parametrize("kind", KINDS)
def test_every_kind_is_in_openapi_with_its_fields_units_and_limits(
    openapi: dict[str, Any], kind: str
) -> None:
    component = _component(openapi, kind)
    properties = component["properties"]
    fields = kind_fields(SETPOINT_KINDS[kind])

    assert properties["type"]["const"] == kind
    assert list(properties) == ["type", *(field.name for field in fields)]
    assert component["required"] == ["type"] + [f.name for f in fields if f.default is MISSING]
    for field in fields:
        if field.quantity is None:
            continue
        number = _number_schema(properties[field.name])
        assert number.get("x-unit") == field.quantity.unit, field.name
        assert (number["minimum"], number["maximum"]) == (field.quantity.ge, field.quantity.le)


@pytest.mark.parametrize("kind", KINDS)
def test_every_kind_round_trips_through_the_api_model_to_the_link_type(kind: str) -> None:
    setpoint = _sample(SETPOINT_KINDS[kind])

    body = BODY.validate_python(describe(setpoint))

    assert type(body) is SETPOINT_BODIES[kind]
    assert body.to_link() == setpoint
    assert body.model_dump() == describe(setpoint)


@pytest.mark.parametrize(("kind", "field"), QUANTITY_FIELDS, ids=lambda v: getattr(v, "name", v))
@pytest.mark.parametrize("bad", ["above", "below", math.nan, math.inf, -math.inf])
def test_a_number_outside_its_limits_or_not_finite_is_refused_naming_the_field(
    kind: str, field: KindField, bad: str | float
) -> None:
    assert field.quantity is not None
    values = describe(_sample(SETPOINT_KINDS[kind]))
    if bad == "above":
        values[field.name] = field.quantity.le + 1
    elif bad == "below":
        values[field.name] = field.quantity.ge - 1
    else:
        values[field.name] = bad

    with pytest.raises(ValidationError) as refused:
        BODY.validate_python(values)

    assert {error["loc"][-1] for error in refused.value.errors()} == {field.name}
