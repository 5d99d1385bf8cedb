"""The control lease: one pilot client at a time controls a vehicle, and must keep proving it
is there (REST control calls and WebSocket heartbeats renew the lease). A lease that is not
renewed within its TTL lapses; what then happens to the vehicle is the deadman's business."""

from __future__ import annotations

import asyncio
import enum
import secrets
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field


class LeaseEnd(enum.Enum):
    RELEASED = "released"  # DELETE /control
    CLOSED = "closed"  # the WebSocket session that held it went away
    EXPIRED = "expired"  # not renewed within the TTL
    TAKEN_OVER = "taken_over"  # another pilot took control


# Ends after which nobody is flying the vehicle any more.
OPERATOR_LOST = frozenset({LeaseEnd.RELEASED, LeaseEnd.CLOSED, LeaseEnd.EXPIRED})


@dataclass
class Lease:
    lease_id: str
    vehicle_id: int
    holder: str
    session: str  # "rest" or "ws"
    ttl_s: float
    expires_at: float
    busy: int = 0  # control calls in flight; a lease never lapses under a running call
    ended: asyncio.Event = field(default_factory=asyncio.Event)
    end: LeaseEnd | None = None

    def expires_in_s(self, now: float) -> float:
        return max(0.0, self.expires_at - now)


class LeaseHeld(Exception):
    def __init__(self, lease: Lease) -> None:
        super().__init__(f"control of vehicle {lease.vehicle_id} is held by {lease.holder}")
        self.lease = lease


class LeaseInvalid(Exception):
    """The caller's lease id is missing, unknown, or no longer the vehicle's lease."""


LeaseListener = Callable[[Lease, str], None]


def loop_clock() -> float:
    """The running event loop's time, so a lease lapses on the same clock the deadman's
    checker sleeps on (virtual in tests); time.monotonic, the loop's own clock on Linux,
    where no loop runs."""
    try:
        return asyncio.get_running_loop().time()
    except RuntimeError:
        return time.monotonic()


class LeaseManager:
    def __init__(self, ttl_s: float, clock: Callable[[], float] = loop_clock) -> None:
        self.ttl_s = ttl_s
        self._clock = clock
        self._leases: dict[int, Lease] = {}
        self._listeners: list[LeaseListener] = []

    def add_listener(self, listener: LeaseListener) -> None:
        """listener(lease, what) with what in acquired / released / closed / expired /
        taken_over."""
        self._listeners.append(listener)

    def current(self, vehicle_id: int) -> Lease | None:
        return self._leases.get(vehicle_id)

    def acquire(
        self,
        vehicle_id: int,
        holder: str,
        *,
        session: str,
        takeover: bool = False,
        lease_id: str | None = None,
    ) -> Lease:
        """A new lease; re-acquiring with the current lease id just renews it."""
        held = self._leases.get(vehicle_id)
        if held is not None and lease_id is not None and lease_id == held.lease_id:
            return self.renew(vehicle_id, lease_id)
        if held is not None:
            if not takeover:
                raise LeaseHeld(held)
            self._end(held, LeaseEnd.TAKEN_OVER)
        now = self._clock()
        lease = Lease(
            lease_id=secrets.token_urlsafe(16),
            vehicle_id=vehicle_id,
            holder=holder,
            session=session,
            ttl_s=self.ttl_s,
            expires_at=now + self.ttl_s,
        )
        self._leases[vehicle_id] = lease
        self._notify(lease, "acquired")
        return lease

    def renew(self, vehicle_id: int, lease_id: str | None) -> Lease:
        lease = self._leases.get(vehicle_id)
        if (
            lease is None
            or lease_id is None
            or not secrets.compare_digest(lease.lease_id, lease_id)
        ):
            raise LeaseInvalid(
                "this call needs the vehicle's control lease (X-Lease-Id from POST /control)"
                if lease is None or lease_id is None
                else f"the control lease is held by {lease.holder}, not by this lease id"
            )
        lease.expires_at = self._clock() + lease.ttl_s
        return lease

    def release(
        self, vehicle_id: int, lease_id: str | None, end: LeaseEnd = LeaseEnd.RELEASED
    ) -> None:
        lease = self.renew(vehicle_id, lease_id)
        self._end(lease, end)

    @contextmanager
    def hold(self, vehicle_id: int, lease_id: str | None) -> Iterator[Lease]:
        """Renew the lease for one control call and keep it alive until the call returns."""
        lease = self.renew(vehicle_id, lease_id)
        lease.busy += 1
        try:
            yield lease
        finally:
            lease.busy -= 1
            if lease.end is None:
                lease.expires_at = self._clock() + lease.ttl_s

    def expire_due(self) -> list[Lease]:
        """End every lease whose TTL has run out; the checker task calls this."""
        now = self._clock()
        due = [
            lease for lease in self._leases.values() if lease.busy == 0 and lease.expires_at <= now
        ]
        for lease in due:
            self._end(lease, LeaseEnd.EXPIRED)
        return due

    def status(self, vehicle_id: int) -> tuple[str | None, float | None]:
        lease = self._leases.get(vehicle_id)
        if lease is None:
            return None, None
        return lease.holder, round(lease.expires_in_s(self._clock()), 3)

    def _end(self, lease: Lease, end: LeaseEnd) -> None:
        if self._leases.get(lease.vehicle_id) is lease:
            del self._leases[lease.vehicle_id]
        lease.end = end
        lease.ended.set()
        self._notify(lease, end.value)

    def _notify(self, lease: Lease, what: str) -> None:
        for listener in self._listeners:
            listener(lease, what)
