"""What every request and error shares: strict bodies, error answers, the health answer,
and the command bodies' number types with the limits and units the setpoint kinds define."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field
from pydantic.fields import FieldInfo

from skyhelm_wire.setpoint_kinds import AltitudeM, Degrees, LatitudeDeg, LongitudeDeg, quantity_of


def limits_of(hint: Any) -> FieldInfo:
    """pydantic's form of the Quantity in a link type: its range, and its unit as x-unit."""
    quantity = quantity_of(hint)
    if quantity is None:
        raise TypeError(f"{hint!r} carries no Quantity")
    limits: FieldInfo = Field(ge=quantity.ge, le=quantity.le)
    if quantity.unit is not None:
        limits = Field(ge=quantity.ge, le=quantity.le, json_schema_extra={"x-unit": quantity.unit})
    return limits


def _whole(value: Any) -> Any:
    """JSON has one number type: 3.0 is an integer where the schema asks for one."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


# the last annotation of an integer in a strict body, after its limits: 3 or 3.0, never
# true or "3"
WHOLE = BeforeValidator(_whole)
LatDeg = Annotated[float, limits_of(LatitudeDeg)]
LonDeg = Annotated[float, limits_of(LongitudeDeg)]
AltM = Annotated[float, limits_of(AltitudeM)]
YawDeg = Annotated[float | None, limits_of(Degrees)]


class StrictBody(BaseModel):
    """A request body: unknown fields, NaN/inf and a value of another JSON type than the
    schema's (``0`` for a boolean, ``true`` or ``"1"`` for a number) are a 422, never
    passed on."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class ErrorDetail(BaseModel):
    reason: str
    field: str | None = None
    limit: float | None = None
    holder: str | None = None
    retry_after_s: float | None = Field(None, description="429: when to try again (Retry-After)")


class ErrorOut(BaseModel):
    detail: ErrorDetail


class ChildProcessOut(BaseModel):
    """A process the server runs and supervises."""

    name: str = Field(description="'setpoint sender', 'foxglove worker' or 'simulated vehicle'")
    running: bool
    pid: int | None = None
    restarts: int = Field(0, description="started again after a fault")
    faults: int = Field(0, description="deaths and stops seen (kill, crash, no answer)")
    last_fault: str | None = Field(None, description="the last fault and its cause")
    gave_up: bool = Field(False, description="not started again: it failed too often")


class HealthOut(BaseModel):
    status: Literal["ok"]
    version: str
    vehicles: int
    read_only: bool = Field(False, description="a replayed recording: control calls answer 403")
    processes: list[ChildProcessOut] = Field(
        default_factory=list, description="the processes the server runs, as supervised")


class UnprocessableOut(BaseModel):
    detail: list[dict[str, Any]] | ErrorDetail = Field(
        description="pydantic's list of field errors, or the envelope/PX4 refusal"
    )
