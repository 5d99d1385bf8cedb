"""What the MAVLink side (receiver, streams) sees of a simulated vehicle.

`sim.vehicle.SimVehicle` is the one implementation; the receiver and the stream builders
depend on this description instead, so the vehicle can own them without an import cycle.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, TypeAlias

from sim.flight.commander import Commander
from sim.flight.navigator import Navigator
from sim.lib.geo import GeoPoint, LocalOrigin
from sim.lib.params import ParamStore
from sim.lib.topics import TrajectorySetpoint, VehicleStateTruth, VtolState
from sim.models.airframes import AirframeModel
from sim.physics.battery import Battery

# pymavlink messages carry their fields as dynamic attributes.
Message: TypeAlias = Any


class Link(Protocol):
    """A MAVLink link as the vehicle sees it (sim.mavlink.endpoint.UdpLink or a test double)."""

    name: str

    @property
    def has_remote(self) -> bool: ...

    def send(self, msg: Message) -> None: ...


class VehicleInterface(Protocol):
    sysid: int
    compid: int
    airframe_name: str
    now_s: float
    params: ParamStore
    model: AirframeModel
    origin: LocalOrigin
    commander: Commander
    navigator: Navigator
    battery: Battery
    last_trajectory_setpoint: TrajectorySetpoint | None

    @property
    def truth(self) -> VehicleStateTruth: ...

    @property
    def ready(self) -> bool: ...

    @property
    def can_arm(self) -> bool: ...

    @property
    def mav_type(self) -> int: ...

    @property
    def vtol_state(self) -> VtolState: ...

    @property
    def landed_state(self) -> int: ...

    def geodetic(self) -> GeoPoint: ...

    def announce(self, severity: int, text: str) -> None: ...

    def broadcast(self, msg: Message) -> None: ...

    def set_home_here(self) -> None: ...

    def set_home_at(self, lat_deg: float, lon_deg: float, alt_m: float, yaw_rad: float) -> None:
        ...

    def set_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> None: ...

    def within_geofence(self, target_ned_m: Sequence[float]) -> bool: ...
