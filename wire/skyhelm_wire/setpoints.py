"""The setpoint request bodies, built from the setpoint kinds (``setpoint_kinds``).

Nothing here lists a kind or a field: each registered kind becomes a model named
``<Kind>Body`` with a ``type`` literal (the kind's name) and the kind's fields, their limits and
units (``x-unit`` in OpenAPI), so the API, OpenAPI and the page follow the one definition.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Literal

from pydantic import BaseModel, Field, create_model

from skyhelm_wire.common import WHOLE, StrictBody, limits_of
from skyhelm_wire.setpoint_kinds import (
    SETPOINT_KINDS,
    KindField,
    Setpoint,
    SetpointKind,
    describe,
    kind_fields,
)


class SetpointBodyBase(StrictBody):
    """A setpoint as the API takes it; ``to_link`` is the link's setpoint of the same kind."""

    link_type: ClassVar[type[SetpointKind]]

    def to_link(self) -> Setpoint:
        return self.link_type(**self.model_dump(exclude={"type"}))


def _pydantic_type(hint: Any) -> Any:
    """A link field type with its Quantity as pydantic limits (``| None`` kept)."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        members = [_pydantic_type(arg) for arg in typing.get_args(hint)]
        return typing.Union[tuple(members)]  # noqa: UP007 (built from a runtime list)
    if typing.get_origin(hint) is Annotated:
        base = typing.get_args(hint)[0]
        if base is int:
            return Annotated[int, limits_of(hint), WHOLE]
        return Annotated[base, limits_of(hint)]
    return Annotated[int, WHOLE] if hint is int else hint


def _field(field: KindField) -> tuple[Any, Any]:
    default = ... if field.default is dataclasses.MISSING else field.default
    return _pydantic_type(field.hint), default


def _body_model(kind: type[SetpointKind]) -> type[SetpointBodyBase]:
    fields: dict[str, Any] = {"type": (Literal[kind.kind], ...)}
    fields.update((field.name, _field(field)) for field in kind_fields(kind))
    model = create_model(
        f"{kind.__name__}Body",
        __base__=SetpointBodyBase,
        __doc__=kind.__doc__,
        __module__=__name__,
        **fields,
    )
    model.link_type = kind
    return model


# kind name -> request model, in the registry's order
SETPOINT_BODIES: dict[str, type[SetpointBodyBase]] = {
    name: _body_model(kind) for name, kind in SETPOINT_KINDS.items()
}

if TYPE_CHECKING:
    SetpointBody = SetpointBodyBase
else:
    # the discriminated union of every kind's model, so OpenAPI lists them by `type`
    SetpointBody = Annotated[
        typing.Union[tuple(SETPOINT_BODIES.values())],  # noqa: UP007
        Field(discriminator="type"),
    ]


def setpoint_as_dict(setpoint: Setpoint) -> dict[str, Any]:
    """The wire form of a link setpoint: its fields plus the `type` the API names it by."""
    return describe(setpoint)


def setpoint_body(setpoint: Setpoint) -> SetpointBodyBase:
    """The API model of a link setpoint (one the link has checked, so within its limits)."""
    return SETPOINT_BODIES[setpoint.kind].model_validate(describe(setpoint))


class SentSetpointOut(BaseModel):
    setpoint: SetpointBody = Field(description="as sent: the request's shape, offsets resolved")
    message: str = Field(examples=["SET_POSITION_TARGET_LOCAL_NED"])
    frame: int
    type_mask: int
