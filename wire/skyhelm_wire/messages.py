"""The WebSockets' messages, each a JSON object named by its ``type``.

The telemetry socket (``/api/v1/ws/telemetry``) sends states (latest wins at the asked
rate), the vehicle's events and STATUSTEXTs, the vehicle list and clicks in the 3D scene.
The control socket (``/api/v1/ws/control``) answers each request with a result, and tells
its holder of the lease, takeover requests and errors.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from skyhelm_wire.control import LeaseOut
from skyhelm_wire.state import VehicleStateOut, VehicleSummaryOut


class StateMessage(VehicleStateOut):
    """A state snapshot: the REST state, with the vehicle's type as ``vehicle_type``."""

    type: Literal["state"]  # names the message here, so the vehicle type is vehicle_type
    vehicle: int
    vehicle_type: str = Field(examples=["QUADROTOR"])
    telemetry_refused: list[str] = Field(
        default_factory=list, description="telemetry streams the vehicle refused to send"
    )


class _Message(BaseModel):
    model_config = ConfigDict(extra="ignore")


class StatusTextMessage(_Message):
    """A STATUSTEXT the vehicle sent, its chunks joined."""

    type: Literal["statustext"]
    vehicle: int
    time_s: float
    severity: str = Field(examples=["WARNING"])
    text: str


class EventMessage(_Message):
    """Something that happened to the vehicle or its control (``kind`` says what; ``data``
    depends on the kind: docs/api.md lists them)."""

    type: Literal["event"]
    vehicle: int
    kind: str = Field(examples=["armed", "mode_changed", "link_lost", "lease"])
    time_s: float
    data: dict[str, Any]


class VehiclesMessage(_Message):
    """Every vehicle served, sent when the list changes."""

    type: Literal["vehicles"]
    vehicles: list[VehicleSummaryOut]


class SceneClickMessage(_Message):
    """Where a click in the 3D scene met the ground: ENU metres around the first vehicle's
    local origin, and lat/lon once that origin is known."""

    type: Literal["scene_click"]
    seq: int
    time_s: float
    east_m: float
    north_m: float
    up_m: float
    lat_deg: float | None
    lon_deg: float | None
    alt_amsl_m: float | None


if TYPE_CHECKING:
    TelemetryMessage = (
        StateMessage | StatusTextMessage | EventMessage | VehiclesMessage | SceneClickMessage
    )
else:
    TelemetryMessage = Annotated[
        StateMessage | StatusTextMessage | EventMessage | VehiclesMessage | SceneClickMessage,
        Field(discriminator="type"),
    ]


class LeaseMessage(LeaseOut):
    """The control socket's lease, once granted."""

    type: Literal["lease"]


class LeaseEndedMessage(_Message):
    """The control socket's lease ended; the socket closes after this message."""

    type: Literal["lease"]
    state: Literal["released", "closed", "expired", "taken_over", "gone", "ended"]
    by: str | None = Field(None, description="taken_over: who took it")


class TakeoverRequestedMessage(_Message):
    """Someone asks the holder for control; answer with ``takeover_answer``."""

    type: Literal["takeover_requested"]
    request_id: str
    by: str
    timeout_s: float


class ControlErrorMessage(_Message):
    """A refusal not tied to one request (the lease, the message rate)."""

    type: Literal["error"]
    reason: str
    field: str | None = None
    limit: float | None = None
    holder: str | None = None
    retry_after_s: float | None = None


class ResultMessage(_Message):
    """The answer to one control request: the REST status and body it would have had."""

    type: Literal["result"]
    id: Any = Field(description="the request's id, as sent")
    request: str = Field(description="the request's type")
    status: int
    ok: bool
    body: Any


ControlMessage = (
    LeaseMessage | LeaseEndedMessage | TakeoverRequestedMessage | ControlErrorMessage
    | ResultMessage
)  # fmt: skip
