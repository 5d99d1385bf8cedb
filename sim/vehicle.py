"""One simulated PX4 vehicle: airframe model, commander, navigator, MAVLink in and out.

`SimVehicle.step()` is the 250 Hz heartbeat of everything and the only thing that moves
its time (`now_s`, sim seconds); `sim.process.run_loop.run_vehicles()` calls it for a group of
vehicles, paced by a wall clock.
"""

from __future__ import annotations

import asyncio
import logging
import math
import os
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from sim.flight.commander import Commander
from sim.flight.land_detector import LandDetector, MavLandedState
from sim.flight.navigator import Navigator
from sim.flight.rtl_direct import RtlPhase
from sim.lib import modes
from sim.lib.geo import GeoPoint, LocalOrigin
from sim.lib.params import ParamReader, ParamStore
from sim.lib.quat import yaw_from_quat
from sim.lib.topics import ControlSetpoint, TrajectorySetpoint, VehicleStateTruth, VtolState
from sim.mavlink.mavlink_messages import MessageFactory
from sim.mavlink.receiver import Receiver
from sim.mavlink.streams import NORMAL_RATES_HZ, ONBOARD_RATES_HZ, StreamSet
from sim.mavlink.vehicle_interface import Link, Message
from sim.models.airframes import AirframeModel
from sim.models.sim_run import PHYSICS_DT_S
from sim.physics.battery import Battery

__all__ = [
    "BOOT_TIME_S",
    "PHYSICS_DT_S",
    "READY_TIME_S",
    "AirframeFactory",
    "DefaultsFactory",
    "Link",
    "SimVehicle",
    "StatusText",
]

log = logging.getLogger(__name__)

# PX4 SITL: first HEARTBEAT (and home) about 1.5 s after start, ready to arm about 3 s.
BOOT_TIME_S = 1.5
READY_TIME_S = 3.0
# While disarmed on the ground home follows the vehicle; refresh it this often.
HOME_FOLLOW_PERIOD_S = 1.0
STATUSTEXT_HISTORY = 200


@dataclass
class StatusText:
    time_s: float
    severity: int
    text: str


AirframeFactory = Callable[[str, ParamReader], AirframeModel]
DefaultsFactory = Callable[[str], dict[str, float | int]]


def _real_time() -> float:
    return 1.0


def _physics() -> tuple[AirframeFactory, DefaultsFactory]:
    from sim.models import airframes

    return airframes.make_airframe, airframes.param_defaults


class SimVehicle:
    def __init__(
        self,
        airframe: str = "quad",
        sysid: int = 1,
        compid: int = 1,
        *,
        spawn_ned_m: Sequence[float] = (0.0, 0.0, 0.0),
        airframe_factory: AirframeFactory | None = None,
        defaults_factory: DefaultsFactory | None = None,
    ) -> None:
        if airframe_factory is None or defaults_factory is None:
            make, defaults = _physics()
            airframe_factory = airframe_factory or make
            defaults_factory = defaults_factory or defaults
        self.airframe_name = airframe
        self.sysid = sysid
        self.compid = compid
        self.params = ParamStore.for_airframe(airframe, defaults_factory(airframe))
        self.params.set("MAV_SYS_ID", sysid)
        self.model = airframe_factory(airframe, self.params)
        self.model.reset(list(spawn_ned_m), 0.0)
        self.params.set("MAV_TYPE", self.model.mav_type)
        # as PX4 SITL's start: PX4_PARAM_<name>=<value> in the environment sets a parameter
        for problem in self.params.set_from_environment(os.environ):
            log.warning("vehicle %d: %s", sysid, problem)
        self.origin = LocalOrigin()
        self.commander = Commander(self.params, self.announce, is_vtol=self.model.is_vtol)
        self.commander.on_arming_change(self._on_arming_change)
        self.navigator = Navigator(
            self.params, self.commander, self.model, self.announce,
            fixed_wing_only=airframe == "plane", ground_vehicle=airframe == "rover",
        )
        self.land_detector = LandDetector(ground_vehicle=airframe == "rover", params=self.params)
        self._plane = airframe == "plane"
        self.battery = Battery(self.params)
        self.messages = MessageFactory(self)
        self.receiver = Receiver(self)
        self.now_s = 0.0
        self.booted = False
        self.statustexts: deque[StatusText] = deque(maxlen=STATUSTEXT_HISTORY)
        self.last_trajectory_setpoint: TrajectorySetpoint | None = None
        self.ready_event: asyncio.Event | None = None
        self._links: list[tuple[Link, StreamSet]] = []
        # sim seconds per wall second, as the loop that steps this vehicle runs it now
        self.wall_speed: Callable[[], float] = _real_time
        self._geo_cache: tuple[float, GeoPoint] | None = None
        self._home_refreshed_s = -math.inf

    # -- composition -------------------------------------------------------------------

    def attach_link(self, link: Link, onboard: bool) -> None:
        """Add a link with PX4's ONBOARD (API) or NORMAL (GCS) stream set."""
        rates = ONBOARD_RATES_HZ if onboard else NORMAL_RATES_HZ
        self._links.append((link, StreamSet(rates, self.messages)))

    def streams_of(self, link: Link) -> StreamSet:
        for candidate, streams in self._links:
            if candidate is link:
                return streams
        raise KeyError(link.name)

    def handle_message(self, link: Link, msg: Message) -> None:
        if self.booted:
            self.receiver.handle(link, msg)

    def broadcast(self, msg: Message) -> None:
        for link, _ in self._links:
            link.send(msg)

    def announce(self, severity: int, text: str) -> None:
        self.statustexts.append(StatusText(self.now_s, severity, text))
        if not self.booted:
            return
        for msg in self.messages.statustexts(severity, text):
            self.broadcast(msg)

    # -- state views -------------------------------------------------------------------

    @property
    def truth(self) -> VehicleStateTruth:
        return self.model.truth

    @property
    def ready(self) -> bool:
        return self.commander.ready

    @property
    def can_arm(self) -> bool:
        return self.commander.can_arm()

    @property
    def armed(self) -> bool:
        return self.commander.armed

    @property
    def mode_name(self) -> str:
        return self.commander.nav_mode.name

    @property
    def mav_type(self) -> int:
        return self.model.mav_type

    @property
    def vtol_state(self) -> VtolState:
        return self.model.vtol_state if self.model.is_vtol else VtolState.UNDEFINED

    @property
    def rtl_phases(self) -> list[RtlPhase]:
        return list(self.navigator.rtl_phases_seen)

    @property
    def landed_state(self) -> int:
        commander = self.commander
        if commander.landed:
            return MavLandedState.ON_GROUND
        mode = commander.nav_mode
        if mode in (modes.AUTO_TAKEOFF, modes.AUTO_VTOL_TAKEOFF):
            return MavLandedState.TAKEOFF
        if mode == modes.AUTO_LAND or (
            mode == modes.AUTO_RTL and self.navigator.rtl_phase == RtlPhase.LAND
        ):
            return MavLandedState.LANDING
        return MavLandedState.IN_AIR

    def geodetic(self) -> GeoPoint:
        cached = self._geo_cache
        if cached is not None and cached[0] == self.now_s:
            return cached[1]
        point = self.origin.to_geodetic(*self.truth.position_ned_m)
        self._geo_cache = (self.now_s, point)
        return point

    # -- home and origin ---------------------------------------------------------------

    def set_home_here(self) -> None:
        home = self.commander.home
        geo = self.geodetic()
        home.position_ned_m = list(self.truth.position_ned_m)
        home.yaw_rad = yaw_from_quat(self.truth.q_wxyz)
        home.lat_deg, home.lon_deg, home.alt_m = geo.lat_deg, geo.lon_deg, geo.alt_m
        home.valid = True
        self._home_refreshed_s = self.now_s

    def set_home_at(self, lat_deg: float, lon_deg: float, alt_m: float, yaw_rad: float) -> None:
        home = self.commander.home
        home.position_ned_m = self.origin.to_ned(lat_deg, lon_deg, alt_m)
        home.yaw_rad = yaw_rad if math.isfinite(yaw_rad) else home.yaw_rad
        home.lat_deg, home.lon_deg, home.alt_m = lat_deg, lon_deg, alt_m
        home.valid = True
        self._send_home()

    def set_origin(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """SET_GPS_GLOBAL_ORIGIN: the vehicle stays where it is, its local frame moves."""
        here = self.geodetic()
        self.origin = LocalOrigin(lat_deg, lon_deg, alt_m)
        self.truth.position_ned_m[:] = self.origin.to_ned(here.lat_deg, here.lon_deg, here.alt_m)
        self._geo_cache = None
        home = self.commander.home
        if home.valid:
            home.position_ned_m = self.origin.to_ned(home.lat_deg, home.lon_deg, home.alt_m)

    def within_geofence(self, target_ned_m: Sequence[float]) -> bool:
        home = self.commander.home.position_ned_m
        max_hor = self.params.get("GF_MAX_HOR_DIST")
        max_ver = self.params.get("GF_MAX_VER_DIST")
        horizontal = math.hypot(target_ned_m[0] - home[0], target_ned_m[1] - home[1])
        if max_hor > 0 and horizontal > max_hor:
            return False
        return not (max_ver > 0 and home[2] - target_ned_m[2] > max_ver)

    def _send_home(self) -> None:
        msg = self.messages.home_position()
        if msg is not None:
            self.broadcast(msg)

    def _on_arming_change(self, armed: bool) -> None:
        if armed:
            self.set_home_here()
            self._send_home()

    # -- the 250 Hz step ---------------------------------------------------------------

    def step(self, dt_s: float = PHYSICS_DT_S) -> None:
        self.now_s += dt_s
        now = self.now_s
        booting = not self.booted and now >= BOOT_TIME_S
        if booting:
            self.booted = True
        if not self.commander.ready and now >= READY_TIME_S:
            self._become_ready()
        commander = self.commander
        commander.update(now, self.land_detector.landed)
        setpoint = self._current_setpoint()
        motors_on = commander.armed and commander.nav_mode != modes.TERMINATION
        self.model.step(dt_s, motors_on, setpoint)
        self.land_detector.update(
            dt_s, self.model.truth, commander.armed, self.model.landing,
            fixed_wing=self._plane or self.model.in_fixed_wing_flight,
        )
        self.battery.update(dt_s, self.model.power_fraction if motors_on else 0.0)
        if (
            commander.ready
            and not commander.armed
            and commander.landed
            and now - self._home_refreshed_s >= HOME_FOLLOW_PERIOD_S
        ):
            self.set_home_here()
        if booting and not self.commander.home.valid:
            # PX4 SITL (SIH) has its position, hence home, as its first HEARTBEAT goes out
            # (its HOME_POSITION stream sends it with that HEARTBEAT); arming waits for
            # the rest of its checks (READY_TIME_S)
            self.set_home_here()
        if self.booted:
            for link, streams in self._links:
                streams.tick(now, link, self.wall_speed)

    def _become_ready(self) -> None:
        self.commander.ready = True
        self.set_home_here()
        if self.ready_event is not None:
            self.ready_event.set()

    def _current_setpoint(self) -> ControlSetpoint | None:
        commander = self.commander
        if commander.nav_mode == modes.OFFBOARD:
            setpoint = commander.offboard.setpoint if commander.armed else None
        else:
            setpoint = self.navigator.setpoint(self.now_s, self.model.truth, self.origin.alt_m)
        if isinstance(setpoint, TrajectorySetpoint):
            self.last_trajectory_setpoint = setpoint
        return setpoint
