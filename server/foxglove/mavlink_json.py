"""A decoded MAVLink message as the JSON of its channel: its fields by their MAVLink names,
and `_compid`, the component that sent it. Non-finite floats (PX4 sends NaN for "unset")
become null: JSON has no NaN."""

from __future__ import annotations

import json
import math
from typing import Any

from pymavlink.dialects.v20 import development as mavlink


def _plain(value: Any) -> Any:
    """What json cannot write: bytes (a char field of a message built here), arrays."""
    if isinstance(value, bytes | bytearray):
        return value.decode("utf-8", "replace").rstrip("\0")
    return list(value)


_encode = json.JSONEncoder(separators=(",", ":"), default=_plain).encode


# per message class: its uint8_t arrays, which pymavlink hands out as bytes or str
_BYTE_ARRAYS: dict[type, tuple[str, ...]] = {}


def _byte_arrays(message_class: type[mavlink.MAVLink_message]) -> tuple[str, ...]:
    names = _BYTE_ARRAYS.get(message_class)
    if names is None:
        lengths = dict(zip(message_class.ordered_fieldnames, message_class.array_lengths,
                           strict=False))
        names = _BYTE_ARRAYS[message_class] = tuple(
            name for name, c_type in zip(message_class.fieldnames, message_class.fieldtypes,
                                         strict=False)
            if lengths.get(name, 0) and c_type in ("uint8_t", "int8_t")
        )
    return names


def message_json(msg: mavlink.MAVLink_message) -> bytes:
    fields: dict[str, Any] = {"_compid": msg.get_srcComponent()}
    for name in msg.fieldnames:
        fields[name] = getattr(msg, name)
    for name in _byte_arrays(type(msg)):
        value = fields[name]
        if isinstance(value, str):
            fields[name] = list(value.encode("latin-1"))
        elif isinstance(value, bytes | bytearray):
            fields[name] = list(value)
    text = _encode(fields)
    if "NaN" in text or "Infinity" in text:  # seldom: only then is every value looked at
        text = _encode({name: _finite(value) for name, value in fields.items()})
    return text.encode()


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, list):
        return [_finite(item) for item in value]
    return value
