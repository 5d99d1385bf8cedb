"""The operator's safety envelope and how a move is held to it.

One set of limits guards everything that flies the vehicle somewhere: setpoints (through
``setpoint_checks``), take-off altitude, DO_REPOSITION and the offset and go-to intents. The
link checks each where it sends it (``Action.takeoff``, ``Action.reposition``,
``Offboard.set_setpoint``, the intents), so a Python program driving a ``Vehicle``, REST,
the control socket, the fleet and the page meet the same refusal: a ``SetpointRejected``
naming the offending input (``field``), the bound (``limit``) and, in its reason, the
limit's name, which every API surface answers as the same 422.
"""

from __future__ import annotations

from dataclasses import dataclass

from server.link.codec.geo import ground_distance_m
from server.link.codec.snapshot import HomeState


class SetpointRejected(ValueError):
    """A setpoint or move that PX4 would drop or that leaves the envelope."""

    def __init__(self, reason: str, field: str | None = None, limit: float | None = None):
        super().__init__(reason)
        self.reason = reason
        self.field = field
        self.limit = limit


@dataclass
class Envelope:
    """Operator limits; None switches a limit off. Altitude and distance are from home."""

    max_alt_rel_m: float | None = 120.0
    max_distance_m: float | None = 500.0
    max_speed_xy_m_s: float | None = 12.0
    max_speed_z_m_s: float | None = 5.0


@dataclass(frozen=True)
class GeoTarget:
    """Where a move goes: a point and its altitude above home (None: unchanged/unknown)."""

    lat_deg: float
    lon_deg: float
    alt_rel_m: float | None


def check_limit(
    limit_name: str, value: float | None, limit: float | None, *, field: str, what: str = ""
) -> None:
    """SetpointRejected when ``value`` exceeds ``limit`` (either None: nothing to check)."""
    if value is None or limit is None or value <= limit:
        return
    quantity = limit_name.removeprefix("max_")
    prefix = f"{what} " if what else ""
    raise SetpointRejected(
        f"{prefix}outside the envelope: {quantity} {value:.1f} > {limit_name} {limit:g}",
        field=field,
        limit=limit,
    )


def check_takeoff_altitude(envelope: Envelope, altitude_m: float | None) -> None:
    """A take-off climbs to ``altitude_m`` above home (None: PX4's MIS_TAKEOFF_ALT)."""
    limit = envelope.max_alt_rel_m
    if altitude_m is not None and limit is not None and altitude_m > limit:
        raise SetpointRejected(
            "takeoff altitude above the envelope", field="altitude_m", limit=limit
        )


def check_reposition(
    envelope: Envelope,
    home: HomeState | None,
    lat_deg: float,
    lon_deg: float,
    *,
    alt_amsl_m: float | None,
    alt_rel_m: float | None,
) -> None:
    """DO_REPOSITION flies the vehicle as a setpoint does. Without a home neither the
    distance nor an AMSL altitude's height can be known."""
    height_m = alt_rel_m
    if height_m is None and alt_amsl_m is not None and home is not None:
        height_m = alt_amsl_m - home.alt_amsl_m
    check_target(
        envelope,
        home,
        GeoTarget(lat_deg, lon_deg, height_m),
        what="reposition",
        alt_field="alt_rel_m" if alt_rel_m is not None else "alt_amsl_m",
    )


def check_target(
    envelope: Envelope,
    home: HomeState | None,
    target: GeoTarget,
    *,
    what: str,
    position_field: str = "lat_deg",
    alt_field: str = "alt_rel_m",
) -> None:
    """A move to ``target`` stays within the altitude and distance from home. Without a
    home the distance cannot be known, and only a relative altitude is checked."""
    check_limit(
        "max_alt_rel_m", target.alt_rel_m, envelope.max_alt_rel_m, field=alt_field, what=what
    )
    if home is None:
        return
    distance_m = ground_distance_m(home.lat_deg, home.lon_deg, target.lat_deg, target.lon_deg)
    check_limit(
        "max_distance_m", distance_m, envelope.max_distance_m, field=position_field, what=what
    )
