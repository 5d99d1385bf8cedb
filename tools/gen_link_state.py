"""Write the link's state snapshot (server/link/codec/snapshot.py) from the wire models
(skyhelm_wire.state), so a state field is defined once, on the wire.

    python -m tools.gen_link_state           # rewrite server/link/codec/snapshot.py
    python -m tools.gen_link_state --check   # exit 1 if the checked-in file is not current

Each wire model becomes a frozen dataclass the link fills and the API encodes as it is
(`server/control/views.py`), field for field in the wire's order, with the wire's defaults
and descriptions. The link's types are the wire's with these rules: a list is a tuple (a
snapshot is immutable), a `FloatNaN` is a float (NaN while unknown, null in JSON), a wire
model is its snapshot class, and the few names the API spells differently (`type`, `global`)
or adds around the snapshot (`id`, `lease`) are mapped in FIELDS below. The names the API
writes a renamed field under are the wire's (its alias, or its name), written out as
`API_NAMES` for the API's encoding (`server/control/views.py`), so a name the API shows is
spelt in the wire model only.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
import types
import typing
from pathlib import Path
from typing import Any

from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from skyhelm_wire import messages, signing, state
from tools.generated import write_or_check

OUT = Path(__file__).resolve().parent.parent / "server" / "link" / "codec" / "snapshot.py"

# each wire model and the snapshot class generated from it, in dependency order
CLASSES: tuple[tuple[type[BaseModel], str], ...] = (
    (state.PositionNedOut, "PositionNedState"),
    (state.VelocityNedOut, "VelocityNedState"),
    (state.GlobalOut, "GlobalState"),
    (state.AttitudeOut, "AttitudeState"),
    (state.BatteryOut, "BatteryState"),
    (state.EstimatorOut, "EstimatorState"),
    (state.GpsOut, "GpsState"),
    (state.HomeOut, "HomeState"),
    (state.OriginOut, "OriginState"),
    (state.StatusTextOut, "StatusText"),
    (state.ArmingCheckOut, "ArmingCheck"),
    (state.ArmingChecksOut, "ArmingChecksState"),
    (state.StreamOut, "StreamStats"),
    (state.LinkQualityOut, "LinkQuality"),
    (state.LinkOut, "LinkStats"),
    (state.VehicleStateOut, "VehicleState"),
)
# wire models the link keeps in a module of its own: (module, class)
ELSEWHERE: dict[type[BaseModel], tuple[str, str]] = {
    signing.SigningOut: ("server.link.codec.signing", "SigningStats"),
}
# per class, how a wire field maps onto the snapshot: a new name, a type of the link's, or
# None for a field the API writes around the snapshot (the vehicle id, the lease)
FIELDS: dict[str, dict[str, tuple[str, str | None] | None]] = {
    "VehicleState": {
        "id": None,
        "type": ("mav_type", "str"),
        "global_": ("global_position", None),
        # the resolved setpoint as JSON (describe()): its kind's fields are checked on the wire
        "setpoint": ("setpoint", "dict[str, object] | None"),
        "lease": None,
    },
}
# fields of the snapshot the state's socket message carries beside the REST state
EXTRA: dict[str, tuple[type[BaseModel], tuple[str, ...]]] = {
    "VehicleState": (messages.StateMessage, ("telemetry_refused",)),
}
# keyword-only: built in one place from named parts, never positionally
KW_ONLY = {"VehicleState"}


def _name_of(model: type[BaseModel]) -> str:
    for wire, name in CLASSES:
        if wire is model:
            return name
    if model in ELSEWHERE:
        return ELSEWHERE[model][1]
    raise TypeError(f"{model.__name__} has no snapshot class: add it to CLASSES")


def _type(hint: Any) -> str:
    """A wire type as the link's type expression."""
    origin = typing.get_origin(hint)
    if origin is typing.Annotated:
        inner, *metadata = typing.get_args(hint)
        if any(isinstance(item, state.NanIsNull) for item in metadata):
            return "float"
        return _type(inner)
    if hint is type(None):
        return "None"
    if origin in (typing.Union, types.UnionType):
        return " | ".join(dict.fromkeys(_type(arg) for arg in typing.get_args(hint)))
    if origin is list:
        return f"tuple[{_type(typing.get_args(hint)[0])}, ...]"
    if origin is dict:
        key, value = typing.get_args(hint)
        return f"dict[{_type(key)}, {_type(value)}]"
    if origin is typing.Literal:
        return "Literal[" + ", ".join(repr(arg) for arg in typing.get_args(hint)) + "]"
    if isinstance(hint, type) and issubclass(hint, BaseModel):
        return _name_of(hint)
    if isinstance(hint, type):
        return hint.__name__
    raise TypeError(f"no snapshot type for {hint!r}")


def _default(model: type[BaseModel], name: str, link_type: str) -> str | None:
    info = model.model_fields[name]
    if info.default_factory is not None:
        made = info.default_factory()  # type: ignore[call-arg]
        if isinstance(made, list) and not made:
            return "()"
        return f"field(default_factory={type(made).__name__})"
    if info.default is PydanticUndefined:
        return None
    if info.default is None and "None" not in link_type.split(" | "):
        return None  # the wire tolerates its absence; the link always has it
    return repr(info.default)


def _comment(text: str | None, indent: str) -> list[str]:
    words = " ".join((text or "").split())
    lines: list[str] = []
    while words:
        width = 96 - len(indent)
        cut = len(words) if len(words) <= width else words.rfind(" ", 0, width)
        lines.append(f"{indent}# {words[:cut]}")
        words = words[cut:].strip()
    return lines


def _fields(model: type[BaseModel], name: str) -> list[tuple[str, str, str | None, str | None]]:
    """(name, type, default, description) of each snapshot field, in the wire's order."""
    hints = typing.get_type_hints(model, include_extras=True)
    mapping = FIELDS.get(name, {})
    rows = []
    for wire_name, info in model.model_fields.items():
        if wire_name in mapping and mapping[wire_name] is None:
            continue
        link_name, link_type = mapping.get(wire_name) or (wire_name, None)
        link_type = link_type or _type(hints[wire_name])
        rows.append((link_name, link_type, _default(model, wire_name, link_type), info.description))
    extra_model, extra_names = EXTRA.get(name, (model, ()))
    extra_hints = typing.get_type_hints(extra_model, include_extras=True)
    for extra in extra_names:
        info = extra_model.model_fields[extra]
        link_type = _type(extra_hints[extra])
        rows.append((extra, link_type, _default(extra_model, extra, link_type), info.description))
    return rows


def api_names() -> dict[str, str]:
    """The snapshot's field -> the name the API writes it under, for the fields FIELDS
    renames: the wire field's alias, or its name. Only the top class may rename (the API's
    encoding aliases that class's fields)."""
    names: dict[str, str] = {}
    for model, name in CLASSES:
        for wire_name, mapped in FIELDS.get(name, {}).items():
            if mapped is None or mapped[0] == wire_name:
                continue
            if name != "VehicleState":
                raise TypeError(f"{name}.{wire_name}: only VehicleState's fields may be renamed")
            info = model.model_fields[wire_name]
            names[mapped[0]] = info.serialization_alias or info.alias or wire_name
    return names


def _class(model: type[BaseModel], name: str) -> list[str]:
    frozen = "frozen=True, kw_only=True" if name in KW_ONLY else "frozen=True"
    lines = ["", "", f"@dataclass({frozen})", f"class {name}:"]
    doc = model.__dict__.get("__doc__") or f"As the wire's {model.__name__}."
    wrapped = textwrap.wrap(f'"""{" ".join(doc.split())}"""', 96)
    lines.extend(f"    {line}" for line in wrapped)
    lines.append("")
    for field_name, link_type, default, description in _fields(model, name):
        lines.extend(_comment(description, "    "))
        shown = f" = {default}" if default is not None else ""
        lines.append(f"    {field_name}: {link_type}{shown}")
    return lines


def generate() -> str:
    """The module's text."""
    imports = sorted({f"from {module} import {cls}" for module, cls in ELSEWHERE.values()})
    head = [
        '"""The vehicle state snapshot the link fills: one frozen dataclass per wire model of',
        "skyhelm_wire.state, generated from it by `python -m tools.gen_link_state`; do not edit.",
        'tests/link/test_snapshot.py fails when it is not current."""',
        "",
        "from __future__ import annotations",
        "",
        "from dataclasses import dataclass, field",
        "from typing import Literal",
        "",
        *imports,
    ]
    body = [line for model, name in CLASSES for line in _class(model, name)]
    names = "".join(f'    "{name}",\n' for name in sorted(["API_NAMES", *(n for _, n in CLASSES)]))
    aliases = "".join(f'    "{link}": "{api}",\n' for link, api in api_names().items())
    api = [
        "",
        "",
        "# VehicleState's fields the API writes under the wire's name for them (its alias or",
        "# its field name), where the snapshot's differs",
        f"API_NAMES: dict[str, str] = {{\n{aliases}}}",
    ]
    text = "\n".join(head + body + api) + f"\n\n\n__all__ = [\n{names}]\n"
    # as ruff formats it, so the checked-in file passes `ruff format --check`
    ruff = Path(sys.executable).with_name("ruff")
    formatted = subprocess.run(
        [str(ruff), "format", "--stdin-filename", str(OUT), "-"],
        input=text, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return formatted.stdout


def main(argv: list[str] | None = None) -> int:
    return write_or_check(argv, __doc__, OUT, generate, "python -m tools.gen_link_state")


if __name__ == "__main__":
    raise SystemExit(main())
