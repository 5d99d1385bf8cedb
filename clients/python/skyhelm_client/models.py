"""What the client hands back: command results, the lease, the vehicle's state and the
telemetry socket's messages, each keeping the JSON it came from."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

_T = TypeVar("_T")


@dataclass(frozen=True)
class CommandResult:
    """A command the vehicle accepted (200) or still runs (202, ``in_progress``)."""

    command: str
    result: str
    result_code: int | None
    elapsed_ms: float
    reason: str | None
    status: int = 200

    @property
    def in_progress(self) -> bool:
        return self.result == "IN_PROGRESS"

    @classmethod
    def from_json(cls, body: Mapping[str, Any], status: int = 200) -> CommandResult:
        return cls(
            command=str(body["command"]),
            result=str(body["result"]),
            result_code=body.get("result_code"),
            elapsed_ms=float(body.get("elapsed_ms", 0.0)),
            reason=body.get("reason"),
            status=status,
        )


@dataclass(frozen=True)
class Lease:
    """The control lease as the server granted or renewed it. ``setpoint`` is the setpoint
    the vehicle is flying when control was taken (a new holder starts from it), if any;
    ``taken_from`` the previous holder after a takeover."""

    lease_id: str
    ttl_s: float
    holder: str
    expires_in_s: float
    session: str = "rest"
    since_s: float = 0.0
    setpoint: dict[str, Any] | None = None
    taken_from: str | None = None
    raw: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def from_json(cls, body: Mapping[str, Any]) -> Lease:
        return cls(
            lease_id=str(body["lease_id"]),
            ttl_s=float(body["ttl_s"]),
            holder=str(body.get("holder", "")),
            expires_in_s=float(body.get("expires_in_s") or 0.0),
            session=str(body.get("session", "rest")),
            since_s=float(body.get("since_s") or 0.0),
            setpoint=body.get("setpoint"),
            taken_from=body.get("taken_from"),
            raw=dict(body),
        )


@dataclass(frozen=True)
class Ned:
    """A local NED position (metres from the origin)."""

    north_m: float
    east_m: float
    down_m: float

    def horizontal_distance_m(self, north_m: float, east_m: float) -> float:
        return math.hypot(self.north_m - north_m, self.east_m - east_m)


class _Field(Generic[_T]):
    """A state field read from the JSON as a typed attribute."""

    def __init__(self, key: str, convert: Callable[[Any], _T]) -> None:
        self.key, self.convert = key, convert

    def __get__(self, state: State, owner: type[State] | None = None) -> _T:
        return self.convert(state.get(self.key))


class State(Mapping[str, Any]):
    """A vehicle's state snapshot (``GET /vehicles/{id}``, or a telemetry ``state``
    message). Every field of the JSON is there by key (``state["battery"]``); the ones a
    script reads most have typed properties."""

    def __init__(self, data: Mapping[str, Any]) -> None:
        self._data = dict(data)

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

    mode = _Field("mode", str)
    armed = _Field("armed", bool)
    connected = _Field("connected", bool)
    landed_state = _Field("landed_state", str)

    @property
    def position_ned(self) -> Ned:
        p = self._data.get("position_ned") or {}
        return Ned(p.get("north_m", math.nan), p.get("east_m", math.nan), p.get("down_m", math.nan))

    @property
    def altitude_m(self) -> float:
        """Height above home (NaN before the vehicle reports a position)."""
        position = self._data.get("global") or {}
        if position.get("alt_rel_m") is not None:
            return float(position["alt_rel_m"])
        return -self.position_ned.down_m

    @property
    def setpoint(self) -> dict[str, Any] | None:
        setpoint: dict[str, Any] | None = self._data.get("setpoint")
        return setpoint

    def as_dict(self) -> dict[str, Any]:
        return dict(self._data)


@dataclass(frozen=True)
class Message:
    """One telemetry socket message: ``type`` is ``state``, ``event``, ``statustext``,
    ``vehicles`` or ``scene_click``; ``state`` is set for states, ``kind`` for events."""

    type: str
    data: dict[str, Any]

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
