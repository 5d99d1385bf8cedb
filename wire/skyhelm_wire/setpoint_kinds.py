"""The offboard setpoint kinds: one frozen dataclass each, its fields with unit and limits.

This is the one definition of the setpoint wire format. A kind's name (``position_ned``) is
the ``type`` the API, the state, the events and the page all use; its fields carry their unit
and the range a value may take as ``Annotated`` metadata (``Quantity``), which the API turns
into its request models and OpenAPI, and ``setpoint_checks`` enforces for direct callers.
The ranges keep every number packable into MAVLink's float32 (and lat/lon·1e7 into int32),
so a value the wire cannot carry is refused, never a crash while encoding.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import asdict, dataclass
from typing import Annotated, Any, ClassVar, Literal


@dataclass(frozen=True)
class Quantity:
    """A number's unit and the closed range PX4 and the wire accept (None: not a physical
    quantity, e.g. a MAV_FRAME number)."""

    unit: str | None
    ge: float
    le: float

    def admits(self, value: float) -> bool:
        return self.ge <= value <= self.le


Metres = Annotated[float, Quantity("m", -1.0e6, 1.0e6)]
MetresPerSecond = Annotated[float, Quantity("m/s", -1.0e3, 1.0e3)]
MetresPerSecond2 = Annotated[float, Quantity("m/s^2", -1.0e3, 1.0e3)]
Degrees = Annotated[float, Quantity("deg", -360.0, 360.0)]
DegreesPerSecond = Annotated[float, Quantity("deg/s", -3600.0, 3600.0)]
LatitudeDeg = Annotated[float, Quantity("deg", -90.0, 90.0)]
LongitudeDeg = Annotated[float, Quantity("deg", -180.0, 180.0)]
AltitudeM = Annotated[float, Quantity("m", -1.0e3, 1.0e5)]
# Normalised thrust, as SET_ATTITUDE_TARGET carries it ("1": dimensionless).
Thrust = Annotated[float, Quantity("1", 0.0, 1.0)]

AltFrame = Literal["amsl", "relative", "terrain"]


class SetpointKind:
    """Base of every setpoint kind; ``class X(SetpointKind, kind="x")`` registers one."""

    kind: ClassVar[str]
    # set by @dataclass on each kind; declared so that type checkers see a dataclass
    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]

    def __init_subclass__(cls, *, kind: str, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if kind in SETPOINT_KINDS:
            raise ValueError(f"setpoint kind {kind!r} is defined twice")
        cls.kind = kind
        SETPOINT_KINDS[kind] = cls


# kind name -> class, in definition order (the order OpenAPI lists them in)
SETPOINT_KINDS: dict[str, type[SetpointKind]] = {}

# Any registered kind: the API, the vehicle and the encoder take every one.
Setpoint = SetpointKind


@dataclass(frozen=True)
class PositionNed(SetpointKind, kind="position_ned"):
    """A local NED position; without a yaw it keeps the current heading."""

    north_m: Metres
    east_m: Metres
    down_m: Metres
    yaw_deg: Degrees | None = None


@dataclass(frozen=True)
class VelocityNed(SetpointKind, kind="velocity_ned"):
    """A NED velocity with a yaw or a yaw rate (neither: keep the current heading)."""

    north_m_s: MetresPerSecond
    east_m_s: MetresPerSecond
    down_m_s: MetresPerSecond
    yaw_deg: Degrees | None = None
    yaw_rate_deg_s: DegreesPerSecond | None = None


@dataclass(frozen=True)
class VelocityBody(SetpointKind, kind="velocity_body"):
    """A velocity in the body frame (forward, right, down) and a yaw rate (none: 0)."""

    forward_m_s: MetresPerSecond
    right_m_s: MetresPerSecond
    down_m_s: MetresPerSecond
    yaw_rate_deg_s: DegreesPerSecond | None = None


@dataclass(frozen=True)
class AccelerationNed(SetpointKind, kind="acceleration_ned"):
    """A NED acceleration."""

    north_m_s2: MetresPerSecond2
    east_m_s2: MetresPerSecond2
    down_m_s2: MetresPerSecond2
    yaw_deg: Degrees | None = None


@dataclass(frozen=True)
class PositionVelocityNed(SetpointKind, kind="position_velocity_ned"):
    """A local NED position with the velocity (and optionally acceleration) to fly it at."""

    north_m: Metres
    east_m: Metres
    down_m: Metres
    north_m_s: MetresPerSecond
    east_m_s: MetresPerSecond
    down_m_s: MetresPerSecond
    north_m_s2: MetresPerSecond2 | None = None
    east_m_s2: MetresPerSecond2 | None = None
    down_m_s2: MetresPerSecond2 | None = None
    yaw_deg: Degrees | None = None


@dataclass(frozen=True)
class PositionGlobal(SetpointKind, kind="position_global"):
    """A global position; the altitude is AMSL, above home or above terrain."""

    lat_deg: LatitudeDeg
    lon_deg: LongitudeDeg
    alt_m: AltitudeM
    alt_frame: AltFrame = "amsl"
    yaw_deg: Degrees | None = None


@dataclass(frozen=True)
class Attitude(SetpointKind, kind="attitude"):
    """Roll, pitch and yaw with a normalised thrust."""

    roll_deg: Degrees
    pitch_deg: Degrees
    yaw_deg: Degrees
    thrust: Thrust


@dataclass(frozen=True)
class BodyRates(SetpointKind, kind="body_rates"):
    """Body angular rates with a normalised thrust."""

    roll_rate_deg_s: DegreesPerSecond
    pitch_rate_deg_s: DegreesPerSecond
    yaw_rate_deg_s: DegreesPerSecond
    thrust: Thrust


@dataclass(frozen=True)
class OffsetNed(SetpointKind, kind="offset_ned"):
    """A position relative to where the vehicle is, in NED; sent as a position_ned."""

    north_m: Metres
    east_m: Metres
    down_m: Metres
    yaw_deg: Degrees | None = None


@dataclass(frozen=True)
class OffsetBody(SetpointKind, kind="offset_body"):
    """A position relative to where the vehicle is and where it points; sent as a
    position_ned."""

    forward_m: Metres
    right_m: Metres
    down_m: Metres
    yaw_deg: Degrees | None = None


@dataclass(frozen=True)
class RawLocal(SetpointKind, kind="raw_local"):
    """SET_POSITION_TARGET_LOCAL_NED as PX4 reads it: MAV_FRAME number,
    POSITION_TARGET_TYPEMASK bits, SI units (yaw in rad, yaw_rate in rad/s)."""

    frame: Annotated[int, Quantity(None, 0, 255)]
    type_mask: Annotated[int, Quantity(None, 0, 65535)]
    x: Metres = 0.0
    y: Metres = 0.0
    z: Metres = 0.0
    vx: MetresPerSecond = 0.0
    vy: MetresPerSecond = 0.0
    vz: MetresPerSecond = 0.0
    afx: MetresPerSecond2 = 0.0
    afy: MetresPerSecond2 = 0.0
    afz: MetresPerSecond2 = 0.0
    yaw: Annotated[float, Quantity("rad", -10.0, 10.0)] = 0.0
    yaw_rate: Annotated[float, Quantity("rad/s", -100.0, 100.0)] = 0.0


@dataclass(frozen=True)
class KindField:
    """One field of a kind: its name, its type (``Annotated`` with its Quantity, possibly
    ``| None``), its Quantity if it is a number, and its default (MISSING: required)."""

    name: str
    hint: Any
    quantity: Quantity | None
    default: Any


_FIELDS: dict[type[SetpointKind], tuple[KindField, ...]] = {}


def kind_fields(kind: type[SetpointKind]) -> tuple[KindField, ...]:
    """The fields of a setpoint kind, in order, with their units and limits."""
    if kind not in _FIELDS:
        hints = typing.get_type_hints(kind, include_extras=True)
        _FIELDS[kind] = tuple(
            KindField(f.name, hints[f.name], quantity_of(hints[f.name]), f.default)
            for f in dataclasses.fields(kind)
        )
    return _FIELDS[kind]


def quantity_of(hint: Any) -> Quantity | None:
    """The Quantity in ``Annotated[float, Quantity(...)]``, also inside ``... | None``."""
    if typing.get_origin(hint) is Annotated:
        return next((m for m in hint.__metadata__ if isinstance(m, Quantity)), None)
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        found = (quantity_of(arg) for arg in typing.get_args(hint))
        return next((q for q in found if q is not None), None)
    return None


def describe(sp: Setpoint) -> dict[str, object]:
    """JSON-able form: the kind name as ``type`` plus the fields, as the API accepts it."""
    return {"type": sp.kind, **asdict(sp)}
