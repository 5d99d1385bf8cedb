"""Write the page's typedefs (web/wire.d.js) from the wire models (skyhelm_wire).

    python -m tools.gen_wire_js           # rewrite web/wire.d.js
    python -m tools.gen_wire_js --check   # exit 1 if the checked-in file is not current

Each model becomes a JSDoc ``@typedef`` with one ``@property`` per field, named as on the
wire (``global``, not ``global_``), optional fields in brackets; the unions the sockets
send (``TelemetryMessage``, ``ControlMessage``) and ``SetpointBody`` become union typedefs.
The page imports them for its editor's checks (``@type {import("./wire.d.js").State}``);
the browser never runs anything in the file.
"""

from __future__ import annotations

import typing
from pathlib import Path
from typing import Any

from pydantic import BaseModel, TypeAdapter
from pydantic.json_schema import models_json_schema

from skyhelm_wire import commands, common, control, messages, params, setpoints, signing, state
from tools.generated import write_or_check

OUT = Path(__file__).resolve().parent.parent / "web" / "wire.d.js"
_REF = "#/$defs/"

# what the page reads: every answer and message; nested models come along through $defs
MODELS: tuple[type[BaseModel], ...] = (
    state.VehicleStateOut,
    state.VehicleSummaryOut,
    commands.CommandResultOut,
    control.LeaseOut,
    control.ControlStatusOut,
    control.TakeoverAnswerOut,
    common.ErrorOut,
    common.HealthOut,
    signing.SigningStatusOut,
    setpoints.SentSetpointOut,
    params.ParamsOut,
    params.ParamOut,
    params.ParamMetadataOut,
    *setpoints.SETPOINT_BODIES.values(),
    *typing.get_args(typing.get_args(messages.TelemetryMessage)[0]),
    *typing.get_args(messages.ControlMessage),
)
UNIONS: dict[str, Any] = {
    "SetpointBody": setpoints.SetpointBody,
    "TelemetryMessage": messages.TelemetryMessage,
    "ControlMessage": messages.ControlMessage,
}


def _js_type(schema: dict[str, Any]) -> str:
    """A JSON schema as a JSDoc type expression."""
    if "$ref" in schema:
        return str(schema["$ref"]).removeprefix(_REF)
    if "const" in schema:
        return _literal(schema["const"])
    if "enum" in schema:
        return "|".join(_literal(value) for value in schema["enum"])
    for key in ("anyOf", "oneOf"):
        if key in schema:
            return "|".join(dict.fromkeys(_js_type(member) for member in schema[key]))
    kind = schema.get("type")
    if kind == "array":
        return f"Array<{_js_type(schema.get('items', {}))}>"
    if kind == "object":
        values = schema.get("additionalProperties")
        return f"Object<string, {_js_type(values)}>" if isinstance(values, dict) else "Object"
    simple = {"string": "string", "integer": "number", "number": "number", "boolean": "boolean"}
    return simple.get(str(kind), "null" if kind == "null" else "*")


def _literal(value: Any) -> str:
    return f'"{value}"' if isinstance(value, str) else str(value).lower()


def _comment(text: str | None) -> list[str]:
    return [f" * {line}".rstrip() for line in (text or "").strip().splitlines()]


def _typedef(name: str, schema: dict[str, Any]) -> list[str]:
    lines = ["/**", *_comment(schema.get("description")), f" * @typedef {{Object}} {name}"]
    required = set(schema.get("required", ()))
    for field, field_schema in schema.get("properties", {}).items():
        shown = field if field in required else f"[{field}]"
        about = " ".join(str(field_schema.get("description", "")).split())
        unit = field_schema.get("x-unit")
        about = f"{about} ({unit})".strip() if unit else about
        lines.append(f" * @property {{{_js_type(field_schema)}}} {shown} {about}".rstrip())
    return [*lines, " */"]


def _union(name: str, annotation: Any, defs: dict[str, Any]) -> list[str]:
    adapter: TypeAdapter[Any] = TypeAdapter(annotation)
    schema = adapter.json_schema(mode="serialization", ref_template=_REF + "{model}")
    defs.update(schema.pop("$defs", {}))
    return ["/**", f" * @typedef {{{_js_type(schema)}}} {name}", " */"]


def generate() -> str:
    """The file's text."""
    _, top = models_json_schema(
        [(model, "serialization") for model in MODELS], ref_template=_REF + "{model}"
    )
    defs: dict[str, Any] = dict(top.get("$defs", {}))
    unions = [_union(name, annotation, defs) for name, annotation in UNIONS.items()]
    blocks = [_typedef(name, defs[name]) for name in sorted(defs)] + unions
    head = [
        "// Generated from the wire models (skyhelm_wire) by `python -m tools.gen_wire_js`;",
        "// do not edit. tests/test_wire_js.py fails when it is not current.",
        "",
    ]
    body = "\n\n".join("\n".join(block) for block in blocks)
    return "\n".join(head) + "\n" + body + "\n\nexport {};\n"


def main(argv: list[str] | None = None) -> int:
    return write_or_check(argv, __doc__, OUT, generate, "python -m tools.gen_wire_js")


if __name__ == "__main__":
    raise SystemExit(main())
