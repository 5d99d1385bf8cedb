"""What each parameter is, as the vehicle's component metadata says (PX4's parameters.json,
the file QGroundControl's parameter screen reads): group, descriptions, units, range,
default, named values and bits; and the range check a value is held to before it is set.

PX4 serves the file over MAVLink FTP (``component_metadata``); it is read once per vehicle
(and again after a reboot), and shared by every caller.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from server.link.plugins.component_metadata import ComponentMetadata, MetadataError


@dataclass(frozen=True)
class ParamChoice:
    """One named value of a parameter (``values``) or one bit of a bitmask (``bitmask``)."""

    value: float | int
    description: str


@dataclass(frozen=True)
class ParamInfo:
    """One parameter's metadata; None or empty where the metadata says nothing."""

    name: str
    type: str  # PX4's: "Float", "Int32"
    group: str
    category: str
    short_desc: str
    long_desc: str
    units: str
    min: float | None
    max: float | None
    default: float | int | None
    decimal_places: int | None
    increment: float | None
    reboot_required: bool
    values: tuple[ParamChoice, ...]
    bitmask: tuple[ParamChoice, ...]

    def range_text(self) -> str:
        """"0 … 20 m/s", "≥ 0 s", "≤ 5", or "" without limits."""
        unit = f" {self.units}" if self.units else ""
        low, high = _number(self.min), _number(self.max)
        if self.min is not None and self.max is not None:
            return f"{low} … {high}{unit}"
        if self.min is not None:
            return f"≥ {low}{unit}"
        if self.max is not None:
            return f"≤ {high}{unit}"
        return ""

    def out_of_range(self, value: float | int) -> str | None:
        """Why ``value`` is outside the metadata's range, in its words; None when inside."""
        if not math.isfinite(value):
            return f"{self.name}: {value} is not a number"
        below = self.min is not None and value < self.min
        above = self.max is not None and value > self.max
        if not (below or above):
            return None
        words = f" ({self.short_desc})" if self.short_desc else ""
        return f"{self.name}: {_number(value)} is outside {self.range_text()}{words}"


def _number(value: float | int | None) -> str:
    """12.0 → "12", 0.5 → "0.5"."""
    if value is None:
        return ""
    return f"{value:g}" if isinstance(value, float) else str(value)


def _optional_float(raw: Any) -> float | None:
    return float(raw) if isinstance(raw, int | float) and not isinstance(raw, bool) else None


def _choices(raw: Any, key: str) -> tuple[ParamChoice, ...]:
    if not isinstance(raw, list):
        return ()
    return tuple(
        ParamChoice(item[key], str(item.get("description", "")))
        for item in raw
        if isinstance(item, dict) and isinstance(item.get(key), int | float)
    )


def parse_parameters(document: Mapping[str, Any]) -> dict[str, ParamInfo]:
    """PX4's parameters.json (``{"parameters": [...], "version": 1}``) by parameter name;
    entries without a name are skipped."""
    found: dict[str, ParamInfo] = {}
    for raw in document.get("parameters", []):
        if not isinstance(raw, dict) or not isinstance(raw.get("name"), str):
            continue
        default = raw.get("default")
        decimals = raw.get("decimalPlaces")
        found[raw["name"]] = ParamInfo(
            name=raw["name"],
            type=str(raw.get("type", "")),
            group=str(raw.get("group", "")),
            category=str(raw.get("category", "")),
            short_desc=str(raw.get("shortDesc", "")),
            long_desc=str(raw.get("longDesc", "")),
            units=str(raw.get("units", "")),
            min=_optional_float(raw.get("min")),
            max=_optional_float(raw.get("max")),
            default=default if isinstance(default, int | float) else None,
            decimal_places=decimals if isinstance(decimals, int) else None,
            increment=_optional_float(raw.get("increment")),
            reboot_required=bool(raw.get("rebootRequired", False)),
            values=_choices(raw.get("values"), "value"),
            bitmask=_choices(raw.get("bitmask"), "index"),
        )
    return found


class ParamMetadata:
    """A vehicle's parameter metadata, loaded once and shared by every caller.

    A failed load is remembered for ``retry_s`` (the vehicle serves none, or FTP failed), so
    a caller during that time gets the error at once rather than waiting for it again.
    """

    retry_s = 30.0

    def __init__(self, metadata: ComponentMetadata, clock: Callable[[], float]) -> None:
        self._metadata = metadata
        self._clock = clock
        self._loaded: dict[str, ParamInfo] | None = None
        self._task: asyncio.Task[dict[str, ParamInfo]] | None = None
        self._failure: tuple[float, MetadataError] | None = None

    @property
    def loaded(self) -> dict[str, ParamInfo] | None:
        return self._loaded

    async def get(self) -> dict[str, ParamInfo]:
        """Every parameter's metadata by name. MetadataError when the vehicle offers none."""
        if self._loaded is not None:
            return self._loaded
        if self._failure is not None and self._clock() - self._failure[0] < self.retry_s:
            raise self._failure[1]
        if self._task is None or self._task.done():
            self._task = asyncio.get_running_loop().create_task(self._load())
        # shielded: one caller giving up (its request cancelled) does not stop the others'
        return await asyncio.shield(self._task)

    async def _load(self) -> dict[str, ParamInfo]:
        try:
            document = await self._metadata.parameters()
            parsed = parse_parameters(document)
        except MetadataError as e:
            self._failure = (self._clock(), e)
            raise
        except (ValueError, TypeError, KeyError) as e:
            error = MetadataError(f"parameters metadata unreadable: {e}")
            self._failure = (self._clock(), error)
            raise error from e
        self._failure = None
        self._loaded = parsed
        return parsed

    def forget(self) -> None:
        """A rebooted vehicle (new firmware, perhaps): read the metadata again when asked."""
        if self._task is not None and not self._task.done():
            self._task.cancel()
        self._task = None
        self._loaded = None
        self._failure = None
