"""The operator deadman. The server keeps streaming setpoints, which defeats PX4's own
offboard-loss failsafe, so when the control lease ends without a new pilot (expired, socket
closed, released) while the streamer runs, the configured on_operator_loss action is applied
and announced as a "deadman" event. Lease changes are announced as "lease" events."""

from __future__ import annotations

import asyncio
import contextlib
import logging

from server.api.lease import OPERATOR_LOST, Lease, LeaseManager
from server.api.registry import VehicleRegistry
from server.api.schemas import setpoint_as_dict
from server.link import CommandResult, Vehicle
from server.settings import OperatorLossAction

log = logging.getLogger(__name__)

# The lease checker's period: a lapse is noticed at most this late (≥ 10 Hz).
CHECK_PERIOD_S = 0.05
_OPERATOR_LOST_NAMES = frozenset(end.value for end in OPERATOR_LOST)


class Deadman:
    def __init__(
        self, leases: LeaseManager, registry: VehicleRegistry, action: OperatorLossAction
    ) -> None:
        self._leases = leases
        self._registry = registry
        self.action: OperatorLossAction = action
        self._checker: asyncio.Task[None] | None = None
        self._actions: set[asyncio.Task[None]] = set()
        leases.add_listener(self._on_lease)

    async def start(self) -> None:
        self._checker = asyncio.create_task(self._check_leases(), name="lease-checker")

    async def stop(self) -> None:
        tasks = [t for t in (self._checker, *self._actions) if t is not None]
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def _check_leases(self) -> None:
        while True:
            self._leases.expire_due()
            await asyncio.sleep(CHECK_PERIOD_S)

    def _on_lease(self, lease: Lease, what: str) -> None:
        vehicle = self._registry.get(lease.vehicle_id)
        if vehicle is None:
            return
        vehicle.publish_event(
            "lease", {"action": what, "holder": lease.holder, "session": lease.session}
        )
        if what in _OPERATOR_LOST_NAMES and vehicle.streamer_active:
            task = asyncio.create_task(self._apply(vehicle, what))
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
        vehicle.publish_event("deadman", event)

    async def _command(self, vehicle: Vehicle) -> CommandResult:
        if self.action == "land":
            return await vehicle.land()
        if self.action == "rtl":
            return await vehicle.return_to_launch()
        return await vehicle.set_mode("HOLD")
