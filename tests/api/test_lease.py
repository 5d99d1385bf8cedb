"""The control lease's rules, on a fake clock."""

from __future__ import annotations

import pytest

from server.api.lease import LeaseEnd, LeaseHeld, LeaseInvalid, LeaseManager


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def leases(clock: FakeClock) -> LeaseManager:
    return LeaseManager(ttl_s=2.0, clock=clock)


def test_second_pilot_is_refused_while_the_lease_is_held(leases: LeaseManager) -> None:
    first = leases.acquire(1, "alice", session="rest")
    with pytest.raises(LeaseHeld) as refused:
        leases.acquire(1, "bob", session="rest")
    assert refused.value.lease is first
    assert leases.current(1) is first


def test_takeover_ends_the_old_lease_as_taken_over(leases: LeaseManager) -> None:
    seen: list[tuple[str, str]] = []
    leases.add_listener(lambda lease, what: seen.append((lease.holder, what)))
    first = leases.acquire(1, "alice", session="ws")
    second = leases.acquire(1, "bob", session="rest", takeover=True)
    assert first.end is LeaseEnd.TAKEN_OVER
    assert first.ended.is_set()
    assert leases.current(1) is second
    assert seen == [("alice", "acquired"), ("alice", "taken_over"), ("bob", "acquired")]
    with pytest.raises(LeaseInvalid):
        leases.renew(1, first.lease_id)


def test_lease_lapses_after_ttl_without_renewal(leases: LeaseManager, clock: FakeClock) -> None:
    lease = leases.acquire(1, "alice", session="rest")
    clock.now += 1.5
    leases.renew(1, lease.lease_id)
    clock.now += 1.9
    assert leases.expire_due() == []
    clock.now += 0.2
    assert leases.expire_due() == [lease]
    assert lease.end is LeaseEnd.EXPIRED
    assert leases.current(1) is None


def test_lease_never_lapses_while_a_control_call_runs(
    leases: LeaseManager, clock: FakeClock
) -> None:
    lease = leases.acquire(1, "alice", session="rest")
    with leases.hold(1, lease.lease_id):
        clock.now += 10.0
        assert leases.expire_due() == []
    clock.now += 1.0
    assert leases.expire_due() == []
    clock.now += 1.5
    assert leases.expire_due() == [lease]


def test_reacquiring_with_the_current_lease_id_renews_it(
    leases: LeaseManager, clock: FakeClock
) -> None:
    lease = leases.acquire(1, "alice", session="rest")
    clock.now += 1.0
    again = leases.acquire(1, "alice", session="rest", lease_id=lease.lease_id)
    assert again is lease
    assert leases.status(1) == ("alice", 2.0)


def test_wrong_or_missing_lease_id_is_refused(leases: LeaseManager) -> None:
    leases.acquire(1, "alice", session="rest")
    for lease_id in (None, "", "not-the-lease"):
        with pytest.raises(LeaseInvalid):
            leases.renew(1, lease_id)
    with pytest.raises(LeaseInvalid):
        leases.renew(2, "anything")


def test_leases_are_per_vehicle(leases: LeaseManager) -> None:
    one = leases.acquire(1, "alice", session="rest")
    two = leases.acquire(2, "bob", session="rest")
    leases.release(1, one.lease_id)
    assert one.end is LeaseEnd.RELEASED
    assert leases.current(2) is two
