"""JSON schemas for the JSON channels, in the subset Foxglove reads.

Foxglove turns a channel's JSON schema into the field list its Plot and Raw Messages panels
offer, and refuses a schema it cannot read: every property must have one `type`, an object
its `properties`, an array its `items`; no `$ref`, `anyOf`, or `null` type. A value may still
be null at run time (JSON has no NaN). So the API's pydantic models and pymavlink's message
definitions are both rewritten into that subset here, once per channel.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel
from pymavlink.dialects.v20 import development as mavlink

from skyhelm_wire.state import LinkOut, StreamOut, VehicleStateOut

JsonSchema = dict[str, Any]

_KEPT = ("description",)


def foxglove_schema(schema: JsonSchema, defs: JsonSchema | None = None) -> JsonSchema:
    """A JSON schema (pydantic's) rewritten into the subset Foxglove reads."""
    defs = schema.get("$defs", {}) if defs is None else defs
    if "$ref" in schema:
        resolved = defs[schema["$ref"].rsplit("/", 1)[-1]]
        return foxglove_schema({**resolved, **_kept(schema)}, defs)
    alternatives = schema.get("anyOf") or schema.get("oneOf")
    if alternatives:
        return {**_one_of(alternatives, defs), **_kept(schema)}
    kind = schema.get("type")
    if isinstance(kind, list):
        kind = next((k for k in kind if k != "null"), "string")
    if kind == "object":
        properties = schema.get("properties", {})
        return {
            "type": "object",
            **_kept(schema),
            "properties": {name: foxglove_schema(sub, defs) for name, sub in properties.items()},
        }
    if kind == "array":
        items = schema.get("items") or {"type": "number"}
        return {"type": "array", **_kept(schema), "items": foxglove_schema(items, defs)}
    if kind in ("number", "integer", "boolean", "string"):
        return {"type": kind, **_kept(schema)}
    if "const" in schema or "enum" in schema:
        values = schema.get("enum", [schema.get("const")])
        return {"type": "string" if isinstance(values[0], str) else "number", **_kept(schema)}
    return {"type": "string", **_kept(schema)}


def _kept(schema: JsonSchema) -> JsonSchema:
    return {key: schema[key] for key in _KEPT if key in schema}


def _one_of(alternatives: list[JsonSchema], defs: JsonSchema) -> JsonSchema:
    """A nullable value is its non-null type; a union of objects (the setpoint kinds) is one
    object with every field of any of them."""
    kinds = [foxglove_schema(a, defs) for a in alternatives if a.get("type") != "null"]
    if not kinds:
        return {"type": "string"}
    if len(kinds) > 1 and all(k["type"] == "object" for k in kinds):
        merged: JsonSchema = {}
        for kind in kinds:
            merged.update(kind["properties"])
        return {"type": "object", "properties": merged}
    return kinds[0]


def model_schema(model: type[BaseModel], title: str) -> JsonSchema:
    """The JSON the API answers with, as a Foxglove channel schema."""
    schema = foxglove_schema(model.model_json_schema(mode="serialization", by_alias=True))
    return {**schema, "title": title}


class HealthOut(BaseModel):
    """The setpoint stream's figures and the link's counters, as the state shows them."""

    stream: StreamOut
    link: LinkOut


STATE_SCHEMA = model_schema(VehicleStateOut, "skyhelm.VehicleState")
HEALTH_SCHEMA = model_schema(HealthOut, "skyhelm.Health")

_MAVLINK_TYPES = {
    "float": "number", "double": "number", "char": "string",
}  # fmt: skip


def mavlink_schema(msg: mavlink.MAVLink_message) -> JsonSchema:
    """A MAVLink message's fields (units and enums in their descriptions), plus `_compid`:
    the component that sent it (a vehicle's camera and autopilot share a topic). Types
    come from the dialect; where it says too little (messages defined by their wire
    layout only, server.link.codec.px4_messages) the first message's values tell."""
    message_class = type(msg)
    lengths = dict(zip(message_class.ordered_fieldnames, message_class.array_lengths, strict=False))
    units: dict[str, str] = getattr(message_class, "fieldunits_by_name", {})
    enums: dict[str, str] = getattr(message_class, "fieldenums_by_name", {})
    properties: JsonSchema = {"_compid": {"type": "integer", "description": "MAVLink component"}}
    for name, c_type in zip(message_class.fieldnames, message_class.fieldtypes, strict=False):
        kind = _MAVLINK_TYPES.get(c_type, "integer")
        field: JsonSchema = {"type": kind}
        if lengths.get(name, 0) and kind != "string":
            field = {"type": "array", "items": field}
        elif isinstance(getattr(msg, name, None), str | bytes):
            field = {"type": "string"}
        notes = [note for note in (units.get(name), enums.get(name)) if note]
        if notes:
            field["description"] = ", ".join(notes)
        properties[name] = field
    return {"type": "object", "title": f"mavlink.{message_class.msgname}", "properties": properties}
