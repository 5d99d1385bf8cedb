"""The deadman, in two parts that never stand in for each other.

Operator loss: the server keeps streaming setpoints, which defeats PX4's own offboard-loss
failsafe, so when the control lease ends without a new pilot (expired, socket closed,
released) while the streamer runs, the configured on_operator_loss action is applied.

Live inputs: a setpoint or intent marked live (keys, sliders, a gamepad: hold-to-fly) must be
fed again within ``live_timeout_s``; when it is not, the vehicle brakes and holds. Anything
not live (a script's position setpoint) is never cancelled by waiting.

Sticks (MANUAL_CONTROL) are live input too: when none come within ``live_timeout_s`` they
are centred (hold in POSCTL/ALTCTL, hover thrust in STABILIZED) and sent centred for
``STICKS_CENTRED_S``, then no longer sent, so that PX4's own manual control loss failsafe
applies. A lease end does the same at once.

All are announced as "deadman" events; lease changes as "control" events (control_events.py)."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

from server.control.audit import AuditLog
from server.control.control_events import ControlEvents
from server.control.lease import OPERATOR_LOST, Lease, LeaseManager
from server.control.registry import VehicleRegistry
from server.link import CommandResult, SentSetpoint, Vehicle
from server.link.codec.aio import cancel_and_wait
from server.link.intents import brake_then_hold
from server.settings import OperatorLossAction, Settings
from skyhelm_wire.setpoint_kinds import describe as setpoint_as_dict

log = logging.getLogger(__name__)

# The checker's period: a lapsed lease or a silent live input is noticed at most this late.
CHECK_PERIOD_S = 0.05
DEFAULT_LIVE_TIMEOUT_S = 1.0
LIVE_DESCRIPTION = (
    "hold-to-fly input (keys, sliders, a gamepad): unless another live setpoint or intent "
    "follows within deadman_timeout_s, the vehicle brakes and holds"
)
# How long centred sticks are sent after the pilot's went silent, before sending stops.
STICKS_CENTRED_S = 3.0
_OPERATOR_LOST_NAMES = frozenset(end.value for end in OPERATOR_LOST)

Brake = Callable[[Vehicle], Awaitable[SentSetpoint]]


@dataclass
class _LiveWatch:
    due_at: float
    setpoint: object  # the setpoint streamed when last fed: only that one is braked


@dataclass
class _SticksWatch:
    due_at: float
    centred: bool = False  # sent centred since the input went silent: next, stop


class Deadman:
    def __init__(
        self,
        leases: LeaseManager,
        registry: VehicleRegistry,
        action: OperatorLossAction,
        *,
        live_timeout_s: float = DEFAULT_LIVE_TIMEOUT_S,
        audit: AuditLog | None = None,
        brake: Brake = brake_then_hold,
    ) -> None:
        self._leases = leases
        self._registry = registry
        self.action: OperatorLossAction = action
        self.live_timeout_s = live_timeout_s
        # registered first, so a lease's event is published before the action it causes
        self.events = ControlEvents(leases, registry, audit)
        self._brake = brake
        self._live: dict[int, _LiveWatch] = {}
        self._sticks: dict[int, _SticksWatch] = {}
        self.sticks_centred_s = STICKS_CENTRED_S
        self._checker: asyncio.Task[None] | None = None
        self._actions: set[asyncio.Task[None]] = set()
        leases.add_listener(self._on_lease)

    @classmethod
    def from_settings(
        cls, leases: LeaseManager, registry: VehicleRegistry, settings: Settings
    ) -> Deadman:
        return cls(
            leases,
            registry,
            settings.on_operator_loss,
            live_timeout_s=settings.deadman_timeout_s,
            audit=AuditLog(settings.log_dir),
        )

    @property
    def audit(self) -> AuditLog:
        return self.events.audit

    async def start(self) -> None:
        self.audit.load()
        self._checker = asyncio.create_task(self._check(), name="deadman-checker")

    async def stop(self) -> None:
        for task in (self._checker, *self._actions):
            await cancel_and_wait(task)

    # -- live inputs ----------------------------------------------------------------------
    def feed_live(self, vehicle_id: int) -> None:
        """A live setpoint or intent was just accepted: brake unless another comes within
        live_timeout_s."""
        vehicle = self._registry.get(vehicle_id)
        if vehicle is None:
            return
        self._live[vehicle_id] = _LiveWatch(
            self._leases.now() + self.live_timeout_s, vehicle.setpoint
        )

    def stop_live(self, vehicle_id: int) -> None:
        """A setpoint that is not live replaced the live one: waiting no longer brakes."""
        self._live.pop(vehicle_id, None)

    def watch_live(self, vehicle_id: int, *, live: bool) -> None:
        """After a setpoint or intent was accepted: feed the watch if it is live, else end it."""
        if live:
            self.feed_live(vehicle_id)
        else:
            self.stop_live(vehicle_id)

    def live_watched(self, vehicle_id: int) -> bool:
        return vehicle_id in self._live

    # -- sticks ---------------------------------------------------------------------------
    def feed_sticks(self, vehicle_id: int) -> None:
        """Sticks were just taken: centre them unless new ones come within live_timeout_s."""
        self._sticks[vehicle_id] = _SticksWatch(self._leases.now() + self.live_timeout_s)

    def stop_sticks_watch(self, vehicle_id: int) -> None:
        self._sticks.pop(vehicle_id, None)

    def _check_sticks(self) -> None:
        now = self._leases.now()
        for vehicle_id, watch in list(self._sticks.items()):
            if watch.due_at > now:
                continue
            vehicle = self._registry.get(vehicle_id)
            if vehicle is None or not vehicle.sticks_active:
                del self._sticks[vehicle_id]
            elif not watch.centred:
                self._centre_sticks(vehicle, watch, "live_timeout")
            else:
                del self._sticks[vehicle_id]
                vehicle.stop_sticks("deadman: sticks silent")
                self.events.publish(vehicle_id, "deadman", {
                    "action": "stop_sticks", "cause": "live_timeout", "ok": True})

    def _centre_sticks(self, vehicle: Vehicle, watch: _SticksWatch, cause: str) -> None:
        vehicle.centre_sticks()
        watch.centred = True
        watch.due_at = self._leases.now() + self.sticks_centred_s
        self.events.publish(vehicle.sysid, "deadman", {
            "action": "centre_sticks", "cause": cause, "timeout_s": self.live_timeout_s,
            "stop_in_s": self.sticks_centred_s, "ok": True})

    def _check_live(self) -> None:
        now = self._leases.now()
        for vehicle_id, watch in list(self._live.items()):
            if watch.due_at > now:
                continue
            del self._live[vehicle_id]
            vehicle = self._registry.get(vehicle_id)
            # a setpoint set since (a script's, a brake, a hold) is not the live one any more
            if vehicle is None or not vehicle.streamer_active:
                continue
            if vehicle.setpoint != watch.setpoint:
                continue
            self._run(self._brake_for_silence(vehicle))

    async def _brake_for_silence(self, vehicle: Vehicle) -> None:
        event: dict[str, object] = {
            "action": "brake",
            "cause": "live_timeout",
            "timeout_s": self.live_timeout_s,
        }
        try:
            sent = await self._brake(vehicle)
            event.update(ok=True, setpoint=setpoint_as_dict(sent.setpoint))
        except Exception as exc:  # the event must say the brake failed, whatever the cause
            log.exception("deadman brake failed on vehicle %s", vehicle.sysid)
            event.update(ok=False, reason=f"{type(exc).__name__}: {exc}")
        self.events.publish(vehicle.sysid, "deadman", event)

    # -- operator loss --------------------------------------------------------------------
    async def _check(self) -> None:
        while True:
            self._leases.expire_due()
            self._check_live()
            self._check_sticks()
            await asyncio.sleep(CHECK_PERIOD_S)

    def _on_lease(self, lease: Lease, what: str) -> None:
        if what not in _OPERATOR_LOST_NAMES:
            return
        # nobody flies it now: the operator-loss action decides, not the live-input brake
        self._live.pop(lease.vehicle_id, None)
        vehicle = self._registry.get(lease.vehicle_id)
        if vehicle is not None and vehicle.sticks_active:
            # nobody holds the sticks: centred now, then not sent (PX4's failsafe decides)
            watch = self._sticks.setdefault(lease.vehicle_id, _SticksWatch(0.0))
            self._centre_sticks(vehicle, watch, what)
        if vehicle is not None and vehicle.streamer_active:
            self._run(self._apply(vehicle, what))

    def _run(self, action: Awaitable[None]) -> None:
        task = asyncio.ensure_future(action)
        self._actions.add(task)
        task.add_done_callback(self._actions.discard)

    async def _apply(self, vehicle: Vehicle, cause: str) -> None:
        event: dict[str, object] = {"action": self.action, "cause": cause}
        try:
            if self.action == "hold":
                sent = await vehicle.hold_position_setpoint()
                event.update(ok=True, setpoint=setpoint_as_dict(sent.setpoint))
            elif self.action == "continue":
                event.update(ok=True)
            else:
                result = await self._command(vehicle)
                event.update(ok=result.ok, result=result.outcome.name, reason=result.reason)
        except Exception as exc:  # the event must say the action failed, whatever the cause
            log.exception("deadman action %s failed on vehicle %s", self.action, vehicle.sysid)
            event.update(ok=False, reason=f"{type(exc).__name__}: {exc}")
        self.events.publish(vehicle.sysid, "deadman", event)

    async def _command(self, vehicle: Vehicle) -> CommandResult:
        if self.action == "land":
            return await vehicle.land()
        if self.action == "rtl":
            return await vehicle.return_to_launch()
        return await vehicle.set_mode("HOLD")
