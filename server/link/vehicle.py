"""One vehicle on a link: a small core and one plugin per MAVLink concern.

The Link creates a Vehicle on the first HEARTBEAT of a new autopilot and then feeds it
every message from that system through handle_message(); the vehicle talks back through
the ``Sender`` it was given (the Link). Like MAVSDK's plugins:

- ``core``: identity, HEARTBEAT and connection, the send path, the one request protocol
  (``commands``), events and state notifications (``server.link.core.vehicle_core``)
- ``action``: arm, take off, land, return, hold, modes, reposition, VTOL, home and origin
- ``offboard``: setpoints, their envelope and stream, OFFBOARD mode
- ``params``: parameters (``server.link.plugins.params``); ``param_metadata``: what each
  one is, from the component metadata the vehicle serves
- ``telemetry``: what the vehicle reported; ``telemetry_requests``: asking for it
- ``px4_events``: PX4's EVENTs decoded with the metadata it serves
  (``server.link.plugins.px4_events``)

Outside the link a plugin is reached only through the vehicle's operations
(``vehicle.arm()``), each defined once in ``server.link.vehicle_operations``.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Mapping

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.aio import cancel_and_wait
from server.link.codec.arming_checks import readiness
from server.link.codec.setpoints import describe
from server.link.core.requests import Requester
from server.link.core.state import VehicleState
from server.link.core.vehicle_core import Sender, VehicleCore
from server.link.plugins.action import Action
from server.link.plugins.arming_modes import mode_to_arm_in
from server.link.plugins.manual_control import ManualControl
from server.link.plugins.mavlink_values import enum_name
from server.link.plugins.offboard import Offboard
from server.link.plugins.outage import OutageReport
from server.link.plugins.param_metadata import ParamMetadata
from server.link.plugins.params import ParamClient
from server.link.plugins.px4_events import Px4Events
from server.link.plugins.reboot import RebootWatch
from server.link.plugins.telemetry import Telemetry
from server.link.plugins.telemetry_requests import TelemetryRequests
from server.link.stream.streamer import DEFAULT_RATE_HZ
from server.link.vehicle_operations import VehicleOperations

log = logging.getLogger(__name__)


class Vehicle(VehicleOperations):
    """A PX4 vehicle seen on a link. Created by the Link on discovery."""

    def __init__(
        self,
        *,
        link: Sender,
        sysid: int,
        compid: int,
        heartbeat: mavlink.MAVLink_heartbeat_message | None = None,
        telemetry_rates_hz: Mapping[int, float] | None = None,
        stream_rate_hz: float = DEFAULT_RATE_HZ,
    ) -> None:
        self.link = link
        self.sysid = sysid
        self.compid = compid
        core = self.core = VehicleCore(
            sender=link, sysid=sysid, compid=compid, heartbeat=heartbeat, snapshot=self.snapshot
        )
        # before the telemetry's handlers: a reboot resets the state, then the message that
        # showed it is taken in
        self.reboot_watch = RebootWatch(core, self._rebooted)
        self._reread: asyncio.Task[None] | None = None
        self.telemetry = Telemetry(clock=core.now, texts=core.texts, publish=core.publish_event)
        core.on_connection(self._connection_changed)
        for kind, handler in self.telemetry.handlers.items():
            core.on_message(kind, handler)
        self.params = ParamClient(core.requests, on_change=self._param_changed)
        core.on_message("PARAM_VALUE", self.params.handle_param_value)
        self.action = Action(core, self.telemetry)
        self.offboard = Offboard(core, self.telemetry, self.action, stream_rate_hz=stream_rate_hz)
        self.action.offboard_streaming = lambda: self.offboard.streamer.active
        self.manual_control = ManualControl(core, self.offboard)
        self.telemetry_requests = TelemetryRequests(core, self.telemetry, telemetry_rates_hz)
        self.px4_events = Px4Events(core, self.telemetry)
        self.param_metadata = ParamMetadata(self.px4_events.metadata, core.now)
        self.outage = OutageReport(core, self.telemetry)

    @property
    def commands(self) -> Requester:
        """The request protocol: its timeouts and retries can be tuned here."""
        return self.core.requests

    async def close(self) -> None:
        self.offboard.close()
        self.manual_control.stop("vehicle closed")
        await self.telemetry_requests.close()
        await self.px4_events.close()
        await self.outage.close()
        await cancel_and_wait(self._reread)
        self.core.hub.close_all()

    # -- loss, return and reboot ----------------------------------------------------------
    def _connection_changed(self, connected: bool) -> None:
        if connected:
            self.telemetry.link_back()
        else:
            self.telemetry.link_lost()

    def _rebooted(self, reason: str) -> None:
        """Nothing the vehicle said before counts: state, stream, parameters, events."""
        log.warning("vehicle %d rebooted (%s)", self.sysid, reason)
        self.core.publish_event("reboot", {"reason": reason, "text": f"vehicle rebooted: {reason}"})
        self.offboard.vehicle_rebooted()
        self.outage.vehicle_rebooted()
        self.telemetry.forget()
        self.telemetry_requests.start()
        self.px4_events.reload()
        self.param_metadata.forget()
        if self._reread is not None:
            self._reread.cancel()
        self._reread = asyncio.get_running_loop().create_task(
            self._reread_params(), name=f"params-reread:{self.sysid}"
        )
        self.core.changed()

    def _param_changed(self, name: str, before: float | int, now: float | int) -> None:
        """The vehicle reports a parameter at another value than before, whoever set it."""
        self.core.publish_event("params", {
            "name": name, "value": now, "previous": before,
            "text": f"{name} is now {now:g} (was {before:g})",
        })  # fmt: skip

    async def _reread_params(self) -> None:
        try:
            values = await self.params.reread()
        except (TimeoutError, ConnectionError) as exc:
            self.core.publish_event("params", {"reread": False, "error": str(exc)})
            return
        if not values:
            return  # none had been read: nothing to read again, and nothing to tell
        self.core.publish_event("params", {
            "reread": True, "count": len(values),
            "text": f"{len(values)} parameters read again after the reboot",
        })  # fmt: skip

    # -- observing --------------------------------------------------------------------
    @property
    def state_version(self) -> int:
        """Changes with every state change: equal versions mean an equal snapshot (apart
        from the ages and the stream figures, which move with the clock)."""
        return self.core.hub.version

    def _waiting_for(self) -> tuple[str, ...]:
        """What a takeoff (home) and an offboard start (a position) still need."""
        t = self.telemetry
        missing = []
        if t.home is None:
            missing.append("home position")
        if t.position_ned is None or t.global_position is None:
            missing.append("position estimate")
        return tuple(missing)

    def snapshot(self) -> VehicleState:
        core, t = self.core, self.telemetry
        setpoint = self.offboard.setpoint
        reported = t.reported()
        return VehicleState(
            **reported,
            sysid=self.sysid,
            compid=self.compid,
            mav_type=enum_name("MAV_TYPE", core.mav_type, "MAV_TYPE_"),
            autopilot=enum_name("MAV_AUTOPILOT", core.autopilot, "MAV_AUTOPILOT_"),
            connected=core.connected,
            last_heartbeat_age_s=core.now() - core.last_heartbeat_s,
            setpoint=describe(setpoint) if setpoint is not None else None,
            stream=self.offboard.streamer.stats(),
            link=self.link.stats(),
            link_quality=core.link_quality,
            lost_reason=core.lost_reason,
            updated_s=core.updated_s,
            telemetry_refused=tuple(sorted(self.telemetry_requests.refused)),
            message_ages_s=t.ages_at(core.now()),
            arming_checks=readiness(
                self.px4_events.checks.report, reported["mode"], t.ready_to_arm,
                t.sensors_unhealthy,
                arm_switches_to=mode_to_arm_in(reported["mode"], self.offboard.streamer.active),
                waiting_for=self._waiting_for(),
            ),
        )
