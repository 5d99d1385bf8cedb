"""The control lease: taking, renewing and handing it over, what the API says about it, and
the audit log's entries."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field

from skyhelm_wire.common import WHOLE, StrictBody
from skyhelm_wire.setpoints import SetpointBody

ClientName = Annotated[
    str | None,
    Field(
        max_length=64,
        description='the client\'s label, shown to others after the token name: "pilot · <label>"',
    ),
]
TtlS = Annotated[
    float | None,
    Field(
        gt=0.0,
        description="lease TTL asked for, within the server's lease_ttl_min_s..lease_ttl_max_s "
        "(default lease_ttl_s)",
        json_schema_extra={"x-unit": "s"},
    ),
]
Session = Literal["rest", "ws"]


class ControlBody(StrictBody):
    takeover: bool = Field(
        default=False,
        description="take control from the holder: asks the holder first unless `force`",
    )
    force: bool = Field(default=False, description="with takeover: take it at once, without asking")
    client_name: ClientName = None
    ttl_s: TtlS = None
    client_pid: Annotated[int, Field(ge=1), WHOLE] | None = Field(
        default=None,
        description="the calling process's id, for a client on the server's machine: once "
        "the server has seen that this process owns the request's connection, the lease "
        "ends as soon as the process exits (docs/control.md)",
    )


class RenewBody(StrictBody):
    ttl_s: TtlS = None
    client_name: ClientName = None


class LeaseOut(BaseModel):
    lease_id: str
    holder: str
    session: Session
    ttl_s: float
    expires_in_s: float
    since_s: float = Field(description="how long this lease has been held")
    setpoint: SetpointBody | None = Field(
        None, description="the setpoint being streamed now (start from it); null when none"
    )
    taken_from: str | None = Field(None, description="the holder this lease took control from")


class LeaseStatusOut(BaseModel):
    """The lease as the vehicle's state shows it."""

    holder: str | None
    expires_in_s: float | None


class TakeoverRequestOut(BaseModel):
    request_id: str
    by: str
    timeout_s: float
    expires_in_s: float


class LeaseEndOut(BaseModel):
    holder: str
    end: Literal["released", "closed", "expired", "taken_over", "gone"] = Field(
        description="gone: the holder's process exited"
    )
    ago_s: float
    holder_pid: int | None = None


class ControlStatusOut(BaseModel):
    """GET /control: who holds it, since when, and a pending takeover request; all null
    while nobody holds it."""

    holder: str | None = Field(default=None, description='"<token name> · <client label>"')
    session: Session | None = None
    since_s: float | None = Field(default=None, description="how long the holder has held it")
    expires_in_s: float | None = Field(
        default=None, description="left of the TTL without a renewal"
    )
    ttl_s: float | None = None
    request: TakeoverRequestOut | None = Field(
        default=None, description="a pending takeover request"
    )
    holder_pid: int | None = Field(
        default=None, description="the holder's process, watched: the lease ends when it exits"
    )
    last_end: LeaseEndOut | None = Field(
        default=None, description="how the vehicle's last lease ended; null when none has"
    )


class TakeoverAnswerBody(StrictBody):
    grant: bool


class TakeoverAnswerOut(BaseModel):
    request_id: str
    grant: bool
    by: str


class AuditEntryOut(BaseModel):
    time_unix_s: float
    vehicle: int
    kind: Literal["control", "deadman"]
    data: dict[str, Any]
