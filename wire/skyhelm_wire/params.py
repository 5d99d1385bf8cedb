"""Vehicle parameters: the value to set and the answers."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, Field

from skyhelm_wire.common import StrictBody


class ParamValueBody(StrictBody):
    value: Annotated[float, Field(ge=-3.4e38, le=3.4e38)] | int = Field(
        description="an integer for INT32 parameters, a number for REAL32"
    )


class ParamsOut(BaseModel):
    params: dict[str, float | int | None]


class ParamOut(BaseModel):
    name: str
    value: float | int | None
