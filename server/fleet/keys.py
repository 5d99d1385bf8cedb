"""The fleet's key space on Zenoh (docs/fleet.md, "Key space").

Every key starts ``skyhelm/<fleet>/<edge>``; a vehicle is ``<edge>/<vehicle id>`` (its id on
its edge, the sysid). Payloads are JSON in the WS API's schema.

    skyhelm/<fleet>/<edge>/alive                     liveliness token of the edge
    skyhelm/<fleet>/<edge>/<id>/alive                liveliness token of a connected vehicle
    skyhelm/<fleet>/<edge>/<id>/state/<tier>         the vehicle's state (GET /vehicles/{id})
    skyhelm/<fleet>/<edge>/<id>/events               vehicle events as on the telemetry socket
    skyhelm/<fleet>/<edge>/<id>/messages             STATUSTEXT / PX4 event texts
    skyhelm/<fleet>/<edge>/<id>/stream               stream health (GET /vehicles/{id}/stream)
    skyhelm/<fleet>/<edge>/api                       queryable: a REST call run by the edge
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

from skyhelm_wire.fleet import FLEET_NAME_PATTERN

ROOT = "skyhelm"
StateTier = Literal["fast", "slow"]
# state tiers: fast for a view that flies, slow for a large fleet's overview
TIER_RATE_HZ: dict[StateTier, float] = {"fast": 10.0, "slow": 1.0}

# fleet and edge names: one key chunk each, no wildcards or separators
_NAME = re.compile(FLEET_NAME_PATTERN)


def check_name(name: str, what: str = "name") -> str:
    """A fleet or edge name: 1-64 of A-Z a-z 0-9 _ - (one Zenoh key chunk)."""
    if not _NAME.match(name):
        raise ValueError(f"{what} must be 1-64 characters of A-Z a-z 0-9 _ -, got {name!r}")
    return name


@dataclass(frozen=True)
class FleetKeys:
    """The key expressions of one fleet."""

    fleet: str

    def __post_init__(self) -> None:
        check_name(self.fleet, "fleet name")

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.fleet}"

    def edge_alive(self, edge: str) -> str:
        return f"{self.prefix}/{edge}/alive"

    def vehicle_alive(self, edge: str, vehicle_id: int) -> str:
        return f"{self.prefix}/{edge}/{vehicle_id}/alive"

    def state(self, edge: str, vehicle_id: int, tier: StateTier) -> str:
        return f"{self.prefix}/{edge}/{vehicle_id}/state/{tier}"

    def events(self, edge: str, vehicle_id: int) -> str:
        return f"{self.prefix}/{edge}/{vehicle_id}/events"

    def messages(self, edge: str, vehicle_id: int) -> str:
        return f"{self.prefix}/{edge}/{vehicle_id}/messages"

    def stream(self, edge: str, vehicle_id: int) -> str:
        return f"{self.prefix}/{edge}/{vehicle_id}/stream"

    def api(self, edge: str) -> str:
        return f"{self.prefix}/{edge}/api"

    # what a fleet server subscribes to
    def all_alive(self) -> str:
        return f"{self.prefix}/**/alive"

    def all_states(self, tier: StateTier) -> str:
        return f"{self.prefix}/*/*/state/{tier}"

    def all_of(self, leaf: Literal["events", "messages", "stream"]) -> str:
        return f"{self.prefix}/*/*/{leaf}"

    def parse(self, key: str) -> tuple[str, int | None, str]:
        """(edge, vehicle id or None, the rest) of a key in this fleet; ValueError if not."""
        parts = str(key).split("/")
        if len(parts) < 4 or parts[0] != ROOT or parts[1] != self.fleet:
            raise ValueError(f"not a key of fleet {self.fleet!r}: {key}")
        edge = parts[2]
        if parts[3].isdigit():
            return edge, int(parts[3]), "/".join(parts[4:])
        return edge, None, "/".join(parts[3:])
