"""What the client hands back: command results, the lease, the vehicle's state and the
telemetry socket's messages, parsed with the wire models (``skyhelm_wire``) the server
answers with, so a field the server renames or drops fails here, not in a script."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Generic, TypeVar

from pydantic import BaseModel, ConfigDict, TypeAdapter

from skyhelm_wire.commands import CommandResultOut
from skyhelm_wire.control import LeaseOut
from skyhelm_wire.messages import StateMessage, TelemetryMessage
from skyhelm_wire.state import VehicleStateOut

_T = TypeVar("_T")
_M = TypeVar("_M", bound=BaseModel)
ParamValues = dict[str, float | int | None]
_PARAM_VALUES: TypeAdapter[ParamValues] = TypeAdapter(ParamValues)
_TELEMETRY: TypeAdapter[TelemetryMessage] = TypeAdapter(TelemetryMessage)


class CommandResult(CommandResultOut):
    """A command the vehicle accepted (200) or still runs (202, ``in_progress``)."""

    model_config = ConfigDict(frozen=True)

    status: int = 200

    @property
    def in_progress(self) -> bool:
        return self.result == "IN_PROGRESS"

    @classmethod
    def from_json(cls, body: Mapping[str, Any], status: int = 200) -> CommandResult:
        return cls.model_validate({**body, "status": status})


class Lease(LeaseOut):
    """The control lease as the server granted or renewed it. ``setpoint`` is the setpoint
    the vehicle is flying when control was taken (a new holder starts from it), if any;
    ``taken_from`` the previous holder after a takeover."""

    model_config = ConfigDict(frozen=True)

    # JSON, as scripts index it (``lease.setpoint["type"]``); checked against its kind first
    setpoint: dict[str, Any] | None = None  # type: ignore[assignment]

    @classmethod
    def from_json(cls, body: Mapping[str, Any]) -> Lease:
        LeaseOut.model_validate(body)
        return cls.model_validate(body)

    @property
    def raw(self) -> dict[str, Any]:
        """The lease as JSON."""
        return self.model_dump(mode="json")


@dataclass(frozen=True)
class Ned:
    """A local NED position (metres from the origin)."""

    north_m: float
    east_m: float
    down_m: float

    def horizontal_distance_m(self, north_m: float, east_m: float) -> float:
        return math.hypot(self.north_m - north_m, self.east_m - east_m)


def _number(value: float | None) -> float:
    return math.nan if value is None else value


class _ModelField(Generic[_T]):
    """A field of the state's model, as a read-only attribute of the state."""

    def __set_name__(self, owner: type[State], name: str) -> None:
        self.name = name

    def __get__(self, state: State, owner: type[State] | None = None) -> _T:
        value: _T = getattr(state.model, self.name)
        return value


class State(Mapping[str, Any]):
    """A vehicle's state snapshot (``GET /vehicles/{id}``, or a telemetry ``state``
    message). Every field of the JSON is there by key (``state["battery"]``), all of them
    typed in ``model``; the ones a script reads most are properties."""

    model: VehicleStateOut

    def __init__(self, data: Mapping[str, Any]) -> None:
        self._data = dict(data)
        self.model = (
            StateMessage if self._data.get("type") == "state" else VehicleStateOut
        ).model_validate(self._data)

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return (
            f"State(mode={self.mode!r}, armed={self.armed}, landed_state="
            f"{self.landed_state!r}, position_ned={self.position_ned})"
        )

    mode = _ModelField[str]()
    armed = _ModelField[bool]()
    connected = _ModelField[bool]()
    landed_state = _ModelField[str]()

    @property
    def position_ned(self) -> Ned:
        """NaN before the vehicle reports a position."""
        p = self.model.position_ned
        if p is None:
            return Ned(math.nan, math.nan, math.nan)
        return Ned(_number(p.north_m), _number(p.east_m), _number(p.down_m))

    @property
    def altitude_m(self) -> float:
        """Height above home (NaN before the vehicle reports a position)."""
        position = self.model.global_
        if position is not None and position.alt_rel_m is not None:
            return position.alt_rel_m
        return -self.position_ned.down_m

    @property
    def ready_to_fly(self) -> bool:
        """PX4's arming checks pass for the mode flown, or would once the server's arm has
        switched mode first (``model.arming_checks``: its verdict, and why not). A vehicle
        just started is not, until its estimator has a position."""
        checks = self.model.arming_checks
        return checks is not None and checks.verdict in ("ready", "arm_switches_mode")

    @property
    def setpoint(self) -> dict[str, Any] | None:
        """The streamed setpoint as JSON (``model.setpoint`` typed)."""
        setpoint: dict[str, Any] | None = self._data.get("setpoint")
        return setpoint

    def as_dict(self) -> dict[str, Any]:
        return dict(self._data)


@dataclass(frozen=True)
class Message:
    """One telemetry socket message: ``type`` is ``state``, ``event``, ``statustext``,
    ``vehicles`` or ``scene_click``; ``state`` is set for states, ``kind`` for events;
    ``model`` is the message typed."""

    type: str
    data: dict[str, Any]

    @cached_property
    def model(self) -> TelemetryMessage:
        return _TELEMETRY.validate_python(self.data)

    @property
    def vehicle(self) -> int | None:
        vehicle = self.data.get("vehicle")
        return int(vehicle) if vehicle is not None else None

    @property
    def kind(self) -> str | None:
        kind = self.data.get("kind")
        return str(kind) if kind is not None else None

    @property
    def state(self) -> State | None:
        return State(self.data) if self.type == "state" else None


class Answer(Mapping[str, Any], Generic[_M]):
    """A JSON answer by key, as scripts index it (``answer["via"]``), and ``model``: the
    same answer typed with the wire's model the server answers with (``answer.model.via``),
    so a field the server renames fails here and a misspelt one in a script fails mypy."""

    model: _M

    def __init__(self, data: Mapping[str, Any], model_type: type[_M]) -> None:
        self._data = dict(data)
        self.model = model_type.model_validate(self._data)

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return f"Answer({self.model!r})"


def param_values(data: Any) -> ParamValues:
    """``{name: value}`` as GET /params answers it (null: not a finite number)."""
    return _PARAM_VALUES.validate_python(data)


def param_value(value: Any) -> float | None:
    """A parameter's value as GET /params/{name} answers it, as a float (None: not a finite
    number)."""
    return None if value is None else float(value)
