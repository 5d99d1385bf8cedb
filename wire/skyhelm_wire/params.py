"""Vehicle parameters: a value to set, the values read, and what each parameter is (the
vehicle's component metadata, PX4's parameters.json, as QGroundControl shows it)."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, Field

from skyhelm_wire.common import StrictBody


class ParamValueBody(StrictBody):
    value: Annotated[float, Field(ge=-3.4e38, le=3.4e38)] | int = Field(
        description="an integer for INT32 parameters, a number for REAL32"
    )
    force: bool = Field(
        default=False,
        description="set it even outside the range the vehicle's metadata gives (min … max); "
        "without it such a value is refused with 422 naming the range",
    )


class ParamsOut(BaseModel):
    params: dict[str, float | int | None]


class ParamOut(BaseModel):
    name: str
    value: float | int | None = Field(description="the value the vehicle echoed")


class ParamChoiceOut(BaseModel):
    """A named value (``values``: the value) or a bit of a bitmask (``bitmask``: its index)."""

    value: float | int
    description: str


class ParamInfoOut(BaseModel):
    """One parameter as the vehicle's metadata describes it; empty or null where it says
    nothing. ``min``, ``max``, ``default`` and ``increment`` are in ``units``."""

    name: str
    type: str = Field(description="PX4's type name: Float or Int32")
    group: str = Field(description='e.g. "Multicopter Position Control"')
    category: str = Field(description="Standard or Developer")
    short_desc: str
    long_desc: str
    units: str = Field(description='e.g. "m/s"; empty for none')
    min: float | None
    max: float | None
    default: float | int | None = Field(description="the firmware's default")
    decimal_places: int | None
    increment: float | None
    reboot_required: bool = Field(description="a new value takes effect after a reboot")
    values: list[ParamChoiceOut] = Field(description="named values, for an enumeration")
    bitmask: list[ParamChoiceOut] = Field(description="named bits (value = bit index)")


class ParamMetadataOut(BaseModel):
    """Every parameter the vehicle's metadata describes, by name. A vehicle that serves no
    metadata answers ``available`` false with the reason in ``error``."""

    available: bool
    error: str | None = None
    parameters: dict[str, ParamInfoOut]
