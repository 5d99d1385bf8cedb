"""A fleet server's reads (``--fleet``): its edges and every vehicle heard from."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field

# a fleet's or an edge's name is one Zenoh key chunk: no separators or wildcards
FLEET_NAME_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"


class FleetEdgeOut(BaseModel):
    edge: str
    alive: bool
    vehicles: list[int] = Field(description="ids (sysids) of the vehicles heard from it")


class FleetOut(BaseModel):
    fleet: str
    edges: list[FleetEdgeOut]


class FleetVehicleOut(BaseModel):
    key: str = Field(description="<edge>/<id>")
    edge: str
    id: int
    alive: bool = Field(description="its liveliness token is present")
    age_s: float | None = Field(description="since its last state arrived here")
    state_age_s: float | None = Field(description="now - the edge's sent_unix_s")
    controller: str | None = Field(description="who holds its control lease")
    type: str | None
    mode: str | None
    armed: bool | None
    connected: bool | None
    global_: dict[str, Any] | None = Field(alias="global")
    position_ned: dict[str, Any] | None


class FleetVehiclePath(BaseModel):
    edge: str = Field(pattern=FLEET_NAME_PATTERN, description="the edge's name in the fleet")
    vehicle_id: int = Field(ge=0, le=255)
