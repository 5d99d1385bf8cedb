"""What a Vehicle offers: each operation of its core and plugins, defined once here.

Code outside the link reaches a plugin only through these (``vehicle.arm()``, not
``vehicle.action.arm()``; tests/test_vehicle_surface.py holds it to that). Each one names the
plugin doing the work, so going to its definition leads there in one more step.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from typing import Generic, Self, TypeVar, overload

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.commands import CommandResult
from server.link.codec.setpoint_checks import Envelope
from server.link.codec.setpoints import SentSetpoint, Setpoint
from server.link.codec.snapshot import HomeState, StreamStats
from server.link.core.events import VehicleEvent
from server.link.core.liveness import LinkQuality
from server.link.core.state import StateSubscription
from server.link.core.vehicle_core import VehicleCore
from server.link.plugins.action import Action
from server.link.plugins.manual_control import ManualControl, Sticks
from server.link.plugins.offboard import Offboard
from server.link.plugins.param_metadata import ParamInfo, ParamMetadata
from server.link.plugins.params import ParamClient
from server.link.plugins.telemetry import Telemetry

T = TypeVar("T")


class PluginSetting(Generic[T]):
    """A value of the vehicle's core or one of its plugins ("plugin.attribute"), read (and,
    when writable, set) on the vehicle itself."""

    def __init__(self, path: str, *, writable: bool = True) -> None:
        *self._owner_path, self._name = path.split(".")
        self._writable = writable

    def _owner(self, vehicle: object) -> object:
        for name in self._owner_path:
            vehicle = getattr(vehicle, name)
        return vehicle

    @overload
    def __get__(self, vehicle: None, owner: type) -> Self: ...
    @overload
    def __get__(self, vehicle: object, owner: type) -> T: ...
    def __get__(self, vehicle: object | None, owner: type) -> Self | T:
        if vehicle is None:
            return self
        value: T = getattr(self._owner(vehicle), self._name)
        return value

    def __set__(self, vehicle: object, value: T) -> None:
        if not self._writable:
            raise AttributeError(f"{self._name} is reported by the vehicle, not set")
        setattr(self._owner(vehicle), self._name, value)


class VehicleOperations:
    """The Vehicle's operations and settings, each handed to the plugin that owns it."""

    core: VehicleCore
    action: Action
    offboard: Offboard
    manual_control: ManualControl
    params: ParamClient
    param_metadata: ParamMetadata
    telemetry: Telemetry

    # what the core reports, read here
    connected = PluginSetting[bool]("core.connected", writable=False)
    """Whether the link hears the vehicle (``VehicleCore``; changed by set_connected)."""
    lost_reason = PluginSetting[str | None]("core.lost_reason", writable=False)
    """How the link noticed the vehicle's loss ("nothing heard for 1.0 s"), while it is lost."""
    mav_type = PluginSetting[int]("core.mav_type", writable=False)
    """MAV_TYPE from its last HEARTBEAT (``VehicleCore``)."""
    autopilot = PluginSetting[int]("core.autopilot", writable=False)
    """MAV_AUTOPILOT from its last HEARTBEAT (``VehicleCore``)."""
    # settings that live on a plugin, read and set here
    mode_confirm_timeout_s = PluginSetting[float]("action.mode_confirm_timeout_s")
    """How long set_mode waits for the vehicle to report the mode (``Action``)."""
    origin_timeout_s = PluginSetting[float]("action.origin_timeout_s")
    """How long each try of set_gps_origin waits for its echo (``Action``)."""
    envelope = PluginSetting[Envelope]("action.envelope")
    """The limits every move is checked against where it is sent: take-off, reposition
    (``Action``), setpoints (``Offboard``), the intents (``Action.envelope``)."""
    stream_rate_hz = PluginSetting[float]("offboard.streamer.rate_hz")
    """The setpoint stream's rate (``Offboard.streamer``)."""
    offboard_prestream_s = PluginSetting[float]("offboard.prestream_s")
    """How long setpoints stream before OFFBOARD is asked for (``Offboard``)."""

    # -- core: feeding, connection, observing ---------------------------------------------
    def handle_message(self, msg: mavlink.MAVLink_message) -> None:
        """Take in one message from this system (``VehicleCore.handle_message``)."""
        self.core.handle_message(msg)

    def set_connected(
        self, connected: bool, reason: str | None = None, *, silent_since_s: float | None = None
    ) -> None:
        """The link lost the vehicle or heard it again (``VehicleCore.set_connected``)."""
        self.core.set_connected(connected, reason, silent_since_s=silent_since_s)

    def set_link_quality(self, quality: LinkQuality) -> None:
        """The link's figures for this vehicle (``VehicleCore.set_link_quality``)."""
        self.core.set_link_quality(quality)

    def subscribe(self, min_interval_s: float = 0.0) -> StateSubscription:
        """Latest-wins state changes (``SubscriptionHub.subscribe``)."""
        return self.core.hub.subscribe(min_interval_s)

    def subscribe_events(self, maxsize: int = 256) -> asyncio.Queue[VehicleEvent]:
        """A queue of this vehicle's events (``EventHub.subscribe``)."""
        return self.core.events.subscribe(maxsize)

    def unsubscribe_events(self, queue: asyncio.Queue[VehicleEvent]) -> None:
        """Stop filling ``queue`` (``EventHub.unsubscribe``)."""
        self.core.events.unsubscribe(queue)

    def publish_event(self, kind: str, data: dict[str, object]) -> None:
        """Tell every event subscriber (``VehicleCore.publish_event``)."""
        self.core.publish_event(kind, data)

    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Wait until ``predicate()`` holds after some message (``VehicleCore.wait_until``)."""
        return await self.core.wait_until(predicate, timeout_s)

    # -- action: commands and modes -------------------------------------------------------
    async def command_long(
        self, command: int, *params: float, confirm_timeout_s: float | None = None
    ) -> CommandResult:
        """Send COMMAND_LONG and wait for its answer (``Action.command_long``)."""
        return await self.action.command_long(command, *params, confirm_timeout_s=confirm_timeout_s)

    async def arm(self, force: bool = False) -> CommandResult:
        """Arm, into a mode PX4 arms in first if need be (``Action.arm``)."""
        return await self.action.arm(force)

    async def disarm(self, force: bool = False) -> CommandResult:
        """Disarm (``Action.disarm``)."""
        return await self.action.disarm(force)

    async def takeoff(self, altitude_rel_m: float | None = None) -> CommandResult:
        """Climb to altitude_rel_m above home, within the envelope (``Action.takeoff``)."""
        return await self.action.takeoff(altitude_rel_m)

    async def land(self) -> CommandResult:
        """Land here (``Action.land``)."""
        return await self.action.land()

    async def return_to_launch(self) -> CommandResult:
        """Return to launch (``Action.return_to_launch``)."""
        return await self.action.return_to_launch()

    async def hold(self) -> CommandResult:
        """Switch to HOLD (``Action.hold``)."""
        return await self.action.hold()

    async def set_mode(self, mode: str) -> CommandResult:
        """Switch mode and wait until the vehicle reports it (``Action.set_mode``)."""
        return await self.action.set_mode(mode)

    async def reposition(
        self,
        lat_deg: float,
        lon_deg: float,
        *,
        alt_amsl_m: float | None = None,
        alt_rel_m: float | None = None,
        ground_speed_m_s: float | None = None,
        yaw_deg: float | None = None,
        loiter_radius_m: float | None = None,
    ) -> CommandResult:
        """Fly to a place with DO_REPOSITION, within the envelope (``Action.reposition``)."""
        return await self.action.reposition(
            lat_deg, lon_deg, alt_amsl_m=alt_amsl_m, alt_rel_m=alt_rel_m,
            ground_speed_m_s=ground_speed_m_s, yaw_deg=yaw_deg, loiter_radius_m=loiter_radius_m,
        )  # fmt: skip

    async def vtol_transition(
        self,
        to_fixed_wing: bool,
        immediate: bool = False,
        wait: bool = True,
        timeout_s: float = 30.0,
    ) -> CommandResult:
        """Transition a VTOL to fixed wing or back (``Action.vtol_transition``)."""
        return await self.action.vtol_transition(to_fixed_wing, immediate, wait, timeout_s)

    async def set_gps_origin(
        self, lat_deg: float, lon_deg: float, alt_amsl_m: float
    ) -> CommandResult:
        """Set the local frame's GPS origin (``Action.set_gps_origin``)."""
        return await self.action.set_gps_origin(lat_deg, lon_deg, alt_amsl_m)

    async def set_home(
        self,
        lat_deg: float | None = None,
        lon_deg: float | None = None,
        alt_amsl_m: float | None = None,
    ) -> CommandResult:
        """Set home at a place, or here (``Action.set_home``)."""
        return await self.action.set_home(lat_deg, lon_deg, alt_amsl_m)

    # -- offboard: setpoints and their stream ---------------------------------------------
    def check_setpoint(self, sp: Setpoint) -> None:
        """SetpointRejected if the setpoint would be refused (``Offboard.check``)."""
        self.offboard.check(sp)

    async def set_setpoint(self, sp: Setpoint) -> SentSetpoint:
        """Check, send now and keep streaming a setpoint (``Offboard.set_setpoint``)."""
        return await self.offboard.set_setpoint(sp)

    async def hold_position_setpoint(self) -> SentSetpoint:
        """Stream "stay here", outside the envelope too (``Offboard.hold_position``)."""
        return await self.offboard.hold_position()

    async def start_offboard(self, sp: Setpoint | None = None) -> CommandResult:
        """Stream a setpoint, then switch to OFFBOARD (``Offboard.start``)."""
        return await self.offboard.start(sp)

    async def stop_offboard(self, then_mode: str = "HOLD") -> CommandResult:
        """Switch to then_mode, then stop the stream (``Offboard.stop``)."""
        return await self.offboard.stop(then_mode)

    def stream_stats(self) -> StreamStats:
        """The setpoint stream's figures (``Offboard.streamer``)."""
        return self.offboard.streamer.stats()

    @property
    def setpoint(self) -> Setpoint | None:
        """The setpoint streamed last, offsets resolved (``Offboard.setpoint``); it may
        have stopped since (see streamer_active)."""
        return self.offboard.setpoint

    @property
    def streamer_active(self) -> bool:
        """Whether setpoints are being streamed now (``Offboard.streamer``)."""
        return self.offboard.streamer.active

    # -- manual_control: sticks -----------------------------------------------------------
    def set_sticks(self, sticks: Sticks) -> Sticks:
        """Send these sticks from the next tick on (``ManualControl.set_sticks``)."""
        return self.manual_control.set_sticks(sticks)

    def centre_sticks(self) -> Sticks | None:
        """Keep sending, every stick at rest (``ManualControl.centre``)."""
        return self.manual_control.centre()

    def stop_sticks(self, why: str) -> None:
        """Stop sending MANUAL_CONTROL (``ManualControl.stop``)."""
        self.manual_control.stop(why)

    def sticks_stats(self) -> StreamStats:
        """The MANUAL_CONTROL stream's figures (``ManualControl.stats``)."""
        return self.manual_control.stats()

    @property
    def sticks(self) -> Sticks | None:
        """The sticks sent now, None when not sending (``ManualControl.sticks``)."""
        return self.manual_control.sticks

    @property
    def sticks_active(self) -> bool:
        """Whether MANUAL_CONTROL is being sent (``ManualControl.active``)."""
        return self.manual_control.active

    # -- params and telemetry -------------------------------------------------------------
    async def get_param(self, name: str) -> float | int:
        """Read one parameter (``ParamClient.get``)."""
        return await self.params.get(name)

    async def set_param(self, name: str, value: float | int) -> float | int:
        """Set one parameter and check its echo (``ParamClient.set``)."""
        return await self.params.set(name, value)

    async def get_params(self, names: Sequence[str] | None = None) -> dict[str, float | int]:
        """These parameters, or all of them (``ParamClient.get_many``, ``get_all``)."""
        if names is None:
            return await self.params.get_all()
        return await self.params.get_many(names)

    async def get_param_metadata(self) -> dict[str, ParamInfo]:
        """What each parameter is (group, words, units, range, default), as the vehicle's
        component metadata says (``ParamMetadata.get``); MetadataError when it offers none."""
        return await self.param_metadata.get()

    @property
    def home(self) -> HomeState | None:
        """The home position the vehicle reported (``Telemetry.home``)."""
        return self.telemetry.home
