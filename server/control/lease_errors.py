"""What the control lease refuses: a lease held by another, a lease id that is not the
vehicle's lease, a takeover refused, an unknown takeover request, a TTL out of bounds."""

from __future__ import annotations

from typing import Protocol


class HeldLease(Protocol):
    """What a refusal names of the lease that is held."""

    @property
    def vehicle_id(self) -> int: ...

    @property
    def holder(self) -> str: ...


class LeaseHeld(Exception):
    def __init__(self, lease: HeldLease) -> None:
        super().__init__(f"control of vehicle {lease.vehicle_id} is held by {lease.holder}")
        self.lease = lease


class LeaseInvalid(Exception):
    """The caller's lease id is missing, unknown, or no longer the vehicle's lease;
    ``holder`` names who holds it now (None when nobody does)."""

    def __init__(self, reason: str, holder: str | None = None) -> None:
        super().__init__(reason)
        self.holder = holder


class TakeoverRefused(Exception):
    """The holder denied a takeover, did not answer in time, or another ask is pending."""

    def __init__(self, reason: str, holder: str) -> None:
        super().__init__(reason)
        self.holder = holder


class UnknownRequest(LookupError):
    """No pending takeover request with that id (answered, timed out or never made)."""


class TtlOutOfBounds(ValueError):
    def __init__(self, ttl_s: float, limit: float) -> None:
        super().__init__(f"ttl_s {ttl_s:g} is outside the server's bounds; the limit is {limit:g}")
        self.limit = limit
