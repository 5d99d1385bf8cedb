"""MAVLink 2 frames of outgoing messages, packed straight from the messages' fields.

pymavlink's `msg.pack(mav)` builds a header object, two bytearrays and a CRC object for
every message; at about 300 telemetry messages a second per vehicle that is a visible
part of the simulated vehicle's CPU cost. `pack_frame` writes the same bytes (MAVLink 2,
unsigned, trailing zero bytes of the payload trimmed as the protocol allows) from a
recipe per message type read once from pymavlink's generated class. Message types that
are not pymavlink's own generated classes are left to pymavlink (None).

Every frame leaves packable: a field value its wire type cannot hold (an int32 overflow of a
far-away position, a NaN in an integer field, a float beyond float32) is pinned to the
nearest value the type can carry, like a C cast with saturation, instead of raising.
"""

from __future__ import annotations

import math
import operator
import re
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeAlias

from pymavlink.dialects.v20 import development as mavlink

# pymavlink messages carry their fields as dynamic attributes.
Message: TypeAlias = Any

MAVLINK2_STX = 0xFD
_HEADER = struct.Struct("<BBBBBBBHB")
_CRC = struct.Struct("<H")
FLOAT32_MAX = 3.4028234663852886e38
_INT_RANGES: dict[str, tuple[int, int]] = {
    code: (-(1 << (8 * size - 1)), (1 << (8 * size - 1)) - 1) if code.islower()
    else (0, (1 << (8 * size)) - 1)
    for code, size in (("b", 1), ("B", 1), ("h", 2), ("H", 2), ("i", 4), ("I", 4),
                       ("q", 8), ("Q", 8))
}
_FORMAT_ITEM = re.compile(r"(\d*)([a-zA-Z?])")


@dataclass(frozen=True)
class _Recipe:
    payload: struct.Struct
    # one wire type code per packed value (after arrays are flattened)
    codes: str
    fields: Callable[[Message], tuple[Any, ...]]
    # (position, length) of the array fields, which go on the wire element by element
    arrays: tuple[tuple[int, int], ...]
    crc_extra: bytes
    msg_id: int


_recipes: dict[type, _Recipe | None] = {}


def _recipe_for(cls: Any) -> _Recipe | None:  # a pymavlink message class
    if cls.__module__ != mavlink.__name__ or not hasattr(cls, "unpacker"):
        return None
    field_types = dict(zip(cls.fieldnames, cls.fieldtypes, strict=True))
    names: list[str] = []
    arrays: list[tuple[int, int]] = []
    for position, (name, length) in enumerate(
        zip(cls.ordered_fieldnames, cls.array_lengths, strict=True)
    ):
        if field_types[name] == "char":
            names.append(f"_{name}_raw")  # pymavlink keeps a char[] field's bytes here
        else:
            names.append(name)
            if length:
                arrays.append((position, length))
    getter = operator.attrgetter(*names)
    fields: Callable[[Message], tuple[Any, ...]] = (
        getter if len(names) > 1 else lambda msg: (getter(msg),)
    )
    return _Recipe(
        cls.unpacker, _value_codes(cls.unpacker.format), fields, tuple(arrays),
        bytes([cls.crc_extra]), cls.id,
    )


def _value_codes(fmt: str) -> str:
    codes = []
    for count, code in _FORMAT_ITEM.findall(fmt):
        # "50s" is one value (a byte string); "32f" is thirty-two
        codes.append(code if code == "s" else code * int(count or 1))
    return "".join(codes)


def fit_value(code: str, value: Any) -> Any:
    """value as the wire type `code` can carry it: integers saturated (NaN → 0),
    floats beyond float32 saturated to its largest finite magnitude."""
    limits = _INT_RANGES.get(code)
    if limits is not None:
        if isinstance(value, float):
            if math.isnan(value):
                return 0
            if math.isinf(value):
                return limits[0] if value < 0 else limits[1]
            value = round(value)
        low, high = limits
        return low if value < low else high if value > high else value
    if code == "f" and isinstance(value, (int, float)) and math.isfinite(value):
        return max(-FLOAT32_MAX, min(FLOAT32_MAX, float(value)))
    return value


def fit_values(codes: str, values: tuple[Any, ...]) -> tuple[Any, ...]:
    return tuple(fit_value(code, value) for code, value in zip(codes, values, strict=True))


def pack_frame(msg: Message, seq: int, sysid: int, compid: int) -> bytes | None:
    """The MAVLink 2 frame pymavlink would send for msg, or None for foreign types."""
    cls = type(msg)
    try:
        recipe = _recipes[cls]
    except KeyError:
        recipe = _recipes[cls] = _recipe_for(cls)
    if recipe is None:
        return None
    values = recipe.fields(msg)
    if recipe.arrays:
        flat: list[Any] = []
        start = 0
        for position, length in recipe.arrays:
            flat.extend(values[start:position])
            flat.extend(values[position][:length])
            start = position + 1
        flat.extend(values[start:])
        values = tuple(flat)
    try:
        packed = recipe.payload.pack(*values)
    except (struct.error, OverflowError):
        # the rare out-of-range field costs the fitting; normal frames pack directly
        packed = recipe.payload.pack(*fit_values(recipe.codes, values))
    payload = packed.rstrip(b"\0") or b"\0"
    msg_id = recipe.msg_id
    frame = _HEADER.pack(
        MAVLINK2_STX, len(payload), 0, 0, seq, sysid, compid, msg_id & 0xFFFF, msg_id >> 16
    ) + payload
    crc = mavlink.x25crc(frame[1:] + recipe.crc_extra).crc
    return frame + _CRC.pack(crc)
