"""The control lease: one pilot client at a time controls a vehicle, and must keep showing it
is there. The client asks for the TTL (within the server's bounds); every control call, an
explicit renewal and every message on a control socket renew it. A lease that is not renewed
within its TTL lapses; what then happens to the vehicle is the deadman's business.

Taking control from a holder is explicit: forced at once, or asked first, the holder
granting or denying within a timeout (a :class:`TakeoverRequest`)."""

from __future__ import annotations

import asyncio
import contextlib
import enum
import secrets
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Protocol

from server.control.auth import same_secret
from server.control.holder_process import HolderProcess
from server.control.lease_errors import (
    LeaseHeld,
    LeaseInvalid,
    TakeoverRefused,
    TtlOutOfBounds,
    UnknownRequest,
)
from server.settings import Settings

__all__ = [
    "OPERATOR_LOST", "Lease", "LeaseEnd", "LeaseHeld", "LeaseInvalid", "LeaseListener",
    "LeaseManager", "TakeoverRefused", "TakeoverRequest", "TtlOutOfBounds", "UnknownRequest",
]  # fmt: skip


class LeaseEnd(enum.Enum):
    RELEASED = "released"  # DELETE /control
    CLOSED = "closed"  # the WebSocket session that held it went away
    EXPIRED = "expired"  # not renewed within the TTL
    TAKEN_OVER = "taken_over"  # another pilot took control
    GONE = "gone"  # the process that held it exited (holder_process)


# Ends after which nobody is flying the vehicle any more.
OPERATOR_LOST = frozenset({LeaseEnd.RELEASED, LeaseEnd.CLOSED, LeaseEnd.EXPIRED, LeaseEnd.GONE})
# Ended leases remembered by id, so a call with a stale lease id hears who took control.
_ENDED_REMEMBERED = 64


@dataclass
class TakeoverRequest:
    """A pilot asking the holder for control; the holder answers through the future."""

    request_id: str
    by: str
    timeout_s: float
    asked_at: float
    answer: asyncio.Future[bool]


@dataclass
class Lease:
    lease_id: str
    vehicle_id: int
    holder: str
    session: str  # "rest" or "ws"
    ttl_s: float
    expires_at: float
    since: float = 0.0  # on the manager's clock
    busy: int = 0  # control calls in flight; a lease never lapses under a running call
    ended: asyncio.Event = field(default_factory=asyncio.Event)
    end: LeaseEnd | None = None
    taken_from: str | None = None  # the holder this lease took control from
    taken_by: str | None = None  # with TAKEN_OVER: who took it
    forced: bool = False  # with TAKEN_OVER: taken without asking
    renamed_from: str | None = None  # the name before the last rename
    request: TakeoverRequest | None = None  # a pending ask to take this lease
    process: HolderProcess | None = None  # the holder's process, where it could be proved
    ended_at: float | None = None

    def expires_in_s(self, now: float) -> float:
        return max(0.0, self.expires_at - now)


class LeaseListener(Protocol):
    def __call__(self, lease: Lease, what: str, /) -> None: ...


def loop_clock() -> float:
    """The running event loop's time, so a lease lapses on the same clock the deadman's
    checker sleeps on (virtual in tests); time.monotonic, the loop's own clock on Linux,
    where no loop runs."""
    try:
        return asyncio.get_running_loop().time()
    except RuntimeError:
        return time.monotonic()


class LeaseManager:
    def __init__(
        self,
        ttl_s: float,
        clock: Callable[[], float] = loop_clock,
        *,
        min_ttl_s: float | None = None,
        max_ttl_s: float | None = None,
    ) -> None:
        self.ttl_s = ttl_s  # when the client asks none
        self.min_ttl_s = min(ttl_s, min_ttl_s) if min_ttl_s is not None else ttl_s
        self.max_ttl_s = max(ttl_s, max_ttl_s) if max_ttl_s is not None else ttl_s
        self._clock = clock
        self._leases: dict[int, Lease] = {}
        self._ended: OrderedDict[str, Lease] = OrderedDict()
        self._last_ended: dict[int, Lease] = {}
        self._listeners: list[LeaseListener] = []

    @classmethod
    def from_settings(cls, settings: Settings) -> LeaseManager:
        return cls(
            settings.lease_ttl_s,
            min_ttl_s=settings.lease_ttl_min_s,
            max_ttl_s=settings.lease_ttl_max_s,
        )

    def add_listener(self, listener: LeaseListener) -> None:
        """listener(lease, what) with what in acquired / released / closed / expired /
        taken_over / renamed / takeover_requested / takeover_granted / takeover_denied /
        takeover_timed_out / takeover_withdrawn (the last five with ``lease.request`` set)."""
        self._listeners.append(listener)

    def remove_listener(self, listener: LeaseListener) -> None:
        self._listeners.remove(listener)

    def now(self) -> float:
        return self._clock()

    def current(self, vehicle_id: int) -> Lease | None:
        return self._leases.get(vehicle_id)

    def last_ended(self, vehicle_id: int) -> Lease | None:
        return self._last_ended.get(vehicle_id)

    def ttl_for(self, asked_s: float | None) -> float:
        """The TTL a client asked for, or the default; TtlOutOfBounds outside the bounds."""
        if asked_s is None:
            return self.ttl_s
        if not asked_s >= self.min_ttl_s:  # also refuses NaN
            raise TtlOutOfBounds(asked_s, self.min_ttl_s)
        if asked_s > self.max_ttl_s:
            raise TtlOutOfBounds(asked_s, self.max_ttl_s)
        return asked_s

    def acquire(
        self,
        vehicle_id: int,
        holder: str,
        *,
        session: str,
        takeover: bool = False,
        lease_id: str | None = None,
        ttl_s: float | None = None,
        forced: bool = True,
    ) -> Lease:
        """A new lease; re-acquiring with the current lease id just renews it. With
        ``takeover`` the holder's lease ends as TAKEN_OVER (``forced`` says it was not asked)."""
        held = self._leases.get(vehicle_id)
        if held is not None and lease_id is not None and same_secret(lease_id, held.lease_id):
            return self.renew(vehicle_id, lease_id, ttl_s=ttl_s)
        ttl = self.ttl_for(ttl_s)
        if held is not None:
            if not takeover:
                raise LeaseHeld(held)
            held.taken_by = holder
            held.forced = forced
            self._end(held, LeaseEnd.TAKEN_OVER)
        now = self._clock()
        lease = Lease(
            lease_id=secrets.token_urlsafe(16),
            vehicle_id=vehicle_id,
            holder=holder,
            session=session,
            ttl_s=ttl,
            expires_at=now + ttl,
            since=now,
            taken_from=held.holder if held is not None else None,
        )
        self._leases[vehicle_id] = lease
        self._notify(lease, "acquired")
        return lease

    async def take_over(
        self,
        vehicle_id: int,
        holder: str,
        *,
        session: str,
        ask_s: float,
        force: bool = False,
        ttl_s: float | None = None,
    ) -> Lease:
        """Control for ``holder``: at once when nobody holds it or with ``force``; otherwise
        the holder is asked and has ``ask_s`` to grant it. TakeoverRefused when denied,
        unanswered or already being asked; the holder keeps control then."""
        self.ttl_for(ttl_s)  # a bad TTL is refused before anyone is asked
        held = self._leases.get(vehicle_id)
        if held is None or force:
            return self.acquire(
                vehicle_id, holder, session=session, takeover=True, ttl_s=ttl_s, forced=True
            )
        if held.request is not None:
            raise TakeoverRefused(
                f"{held.request.by} is already asking {held.holder} for control", held.holder
            )
        request = TakeoverRequest(
            request_id=secrets.token_urlsafe(8),
            by=holder,
            timeout_s=ask_s,
            asked_at=self._clock(),
            answer=asyncio.get_running_loop().create_future(),
        )
        held.request = request
        self._notify(held, "takeover_requested")
        ended = asyncio.ensure_future(held.ended.wait())
        outcome = "takeover_withdrawn"  # unless the wait below ends: the asker went away
        try:
            waiting: set[asyncio.Future[Any]] = {request.answer, ended}
            await asyncio.wait(waiting, timeout=ask_s, return_when=asyncio.FIRST_COMPLETED)
            outcome = "takeover_timed_out"
        finally:
            ended.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await ended
            if held.request is request:  # neither answered nor ended by the holder
                if held.end is None:
                    self._notify(held, outcome)
                held.request = None
            request.answer.cancel()
        return self._after_asking(held, request, holder, session=session, ttl_s=ttl_s)

    def _after_asking(
        self,
        held: Lease,
        request: TakeoverRequest,
        holder: str,
        *,
        session: str,
        ttl_s: float | None,
    ) -> Lease:
        if held.end is not None:  # the holder let go meanwhile: control is free to take
            try:
                return self.acquire(held.vehicle_id, holder, session=session, ttl_s=ttl_s)
            except LeaseHeld as taken:  # unless someone else took it first
                raise TakeoverRefused(str(taken), taken.lease.holder) from None
        if request.answer.cancelled() or not request.answer.done():
            raise TakeoverRefused(
                f"{held.holder} did not answer within {request.timeout_s:g} s", held.holder
            )
        if not request.answer.result():
            raise TakeoverRefused(f"denied by {held.holder}", held.holder)
        return self.acquire(
            held.vehicle_id, holder, session=session, takeover=True, ttl_s=ttl_s, forced=False
        )

    def answer(
        self, vehicle_id: int, lease_id: str | None, request_id: str, grant: bool
    ) -> TakeoverRequest:
        """The holder's answer to a takeover request (its own lease id proves it is the holder)."""
        lease = self.renew(vehicle_id, lease_id)
        request = lease.request
        if (
            request is None
            or request.answer.done()
            or not same_secret(request_id, request.request_id)
        ):
            raise UnknownRequest(f"no pending takeover request {request_id}")
        # announced while the request is still attached, so the event can name it
        self._notify(lease, "takeover_granted" if grant else "takeover_denied")
        request.answer.set_result(grant)
        lease.request = None
        return request

    def renew(self, vehicle_id: int, lease_id: str | None, *, ttl_s: float | None = None) -> Lease:
        lease = self._leases.get(vehicle_id)
        if (
            lease is None
            or lease_id is None
            or not same_secret(lease_id, lease.lease_id)
        ):
            raise self._invalid(lease, lease_id)
        if ttl_s is not None:
            lease.ttl_s = self.ttl_for(ttl_s)
        lease.expires_at = self._clock() + lease.ttl_s
        return lease

    def rename(self, vehicle_id: int, lease_id: str | None, holder: str) -> Lease:
        lease = self.renew(vehicle_id, lease_id)
        if holder != lease.holder:
            lease.renamed_from, lease.holder = lease.holder, holder
            self._notify(lease, "renamed")
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
        """End every lease whose TTL has run out, or whose holder's process is gone; the
        checker task calls this."""
        now = self._clock()
        due = [
            lease for lease in self._leases.values() if lease.busy == 0 and lease.expires_at <= now
        ]
        gone = [
            lease for lease in self._leases.values()
            if lease not in due and lease.process is not None and lease.process.gone()
        ]  # fmt: skip
        for lease in due:
            self._end(lease, LeaseEnd.EXPIRED)
        for lease in gone:
            self._end(lease, LeaseEnd.GONE)
        return due + gone

    def status(self, vehicle_id: int) -> tuple[str | None, float | None]:
        lease = self._leases.get(vehicle_id)
        if lease is None:
            return None, None
        return lease.holder, round(lease.expires_in_s(self._clock()), 3)

    def _invalid(self, lease: Lease | None, lease_id: str | None) -> LeaseInvalid:
        holder = lease.holder if lease is not None else None
        if lease is None and lease_id is None:
            return LeaseInvalid(
                "this call needs the vehicle's control lease (X-Lease-Id from POST /control)"
            )
        ended = self._ended.get(lease_id) if lease_id else None
        if ended is not None and ended.end is LeaseEnd.TAKEN_OVER:
            return LeaseInvalid(f"this control lease was taken over by {ended.taken_by}", holder)
        if ended is not None and ended.end is not None:
            return LeaseInvalid(f"this control lease has ended ({ended.end.value})", holder)
        if lease is None:
            return LeaseInvalid("nobody holds this vehicle's control lease; take it first")
        if lease_id is None:
            return LeaseInvalid(
                "this call needs the vehicle's control lease (X-Lease-Id from POST /control)",
                holder,
            )
        return LeaseInvalid(
            f"the control lease is held by {lease.holder}, not by this lease id", holder
        )

    def _end(self, lease: Lease, end: LeaseEnd) -> None:
        if self._leases.get(lease.vehicle_id) is lease:
            del self._leases[lease.vehicle_id]
        lease.end = end
        lease.ended_at = self._clock()
        self._last_ended[lease.vehicle_id] = lease
        lease.ended.set()
        if lease.request is not None and not lease.request.answer.done():
            lease.request.answer.cancel()  # the asker stops waiting: control is free
        self._ended[lease.lease_id] = lease
        while len(self._ended) > _ENDED_REMEMBERED:
            self._ended.popitem(last=False)
        self._notify(lease, end.value)

    def _notify(self, lease: Lease, what: str) -> None:
        for listener in self._listeners:
            listener(lease, what)
