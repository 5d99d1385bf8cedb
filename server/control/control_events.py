"""Control events: every change of who controls a vehicle, told to every client of its
telemetry socket (`kind: "control"`) and written to the audit log.

The older `kind: "lease"` event (action, holder, session) is still published beside it,
so clients written against it keep working."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from server.control.audit import AUDIT_KINDS, AuditLog
from server.control.lease import Lease, LeaseEnd, LeaseManager


class _EventVehicle(Protocol):
    def publish_event(self, kind: str, data: dict[str, object]) -> None: ...


class _Vehicles(Protocol):
    def get(self, vehicle_id: int) -> Any: ...


_ENDS = frozenset(end.value for end in LeaseEnd) - {LeaseEnd.TAKEN_OVER.value}


def control_data(lease: Lease, what: str, now: float) -> dict[str, object]:
    """The `data` of a control event: who holds control after it, who held it before."""
    held_s = round(max(0.0, now - lease.since), 3)
    data: dict[str, object] = {"action": what, "session": lease.session}
    if what == "acquired":
        data.update(holder=lease.holder, previous_holder=lease.taken_from, since_s=0.0)
        data["ttl_s"] = lease.ttl_s
    elif what == LeaseEnd.TAKEN_OVER.value:
        data.update(holder=lease.taken_by, previous_holder=lease.holder, since_s=held_s)
        data["forced"] = lease.forced
    elif what in _ENDS:
        data.update(holder=None, previous_holder=lease.holder, since_s=held_s)
    elif what == "renamed":
        data.update(holder=lease.holder, previous_holder=lease.renamed_from, since_s=held_s)
    else:  # the takeover_* steps of asking the holder
        data.update(holder=lease.holder, previous_holder=None, since_s=held_s)
        request = lease.request
        if request is not None:
            data.update(by=request.by, request_id=request.request_id, timeout_s=request.timeout_s)
    return data


class ControlEvents:
    """Publishes lease changes as events and keeps the audit log of control and deadman
    events."""

    def __init__(
        self,
        leases: LeaseManager,
        vehicles: _Vehicles,
        audit: AuditLog | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self.audit = audit if audit is not None else AuditLog(None)
        self._vehicles = vehicles
        self._clock = clock or leases.now
        leases.add_listener(self._on_lease)

    def publish(self, vehicle_id: int, kind: str, data: dict[str, object]) -> None:
        """An event to the vehicle's clients; control and deadman events also to the audit."""
        vehicle: _EventVehicle | None = self._vehicles.get(vehicle_id)
        if vehicle is not None:
            vehicle.publish_event(kind, data)
        if kind in AUDIT_KINDS:
            self.audit.append(vehicle_id, kind, data)

    def _on_lease(self, lease: Lease, what: str) -> None:
        if what in _ENDS or what in ("acquired", LeaseEnd.TAKEN_OVER.value):
            self.publish(
                lease.vehicle_id,
                "lease",
                {"action": what, "holder": lease.holder, "session": lease.session},
            )
        self.publish(lease.vehicle_id, "control", control_data(lease, what, self._clock()))
