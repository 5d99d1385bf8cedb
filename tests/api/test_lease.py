"""The control lease's rules on a fake clock, then leases and the operator deadman on the
event loop's virtual clock."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from types import SimpleNamespace
from typing import cast

import pytest

from server.control.deadman import CHECK_PERIOD_S, Deadman
from server.control.lease import LeaseEnd, LeaseHeld, LeaseInvalid, LeaseManager
from server.control.registry import VehicleRegistry
from server.http.schemas import setpoint_as_dict
from server.link import CommandOutcome, CommandResult, PositionNed
from server.settings import OperatorLossAction


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


# ---- on the event loop's virtual clock, with the deadman watching -------------------------


class _Vehicle:
    """What the deadman uses of a vehicle; records the events and the actions taken."""

    sysid = 1
    sticks_active = False

    def __init__(self, *, streaming: bool = True, fails: bool = False) -> None:
        self.streamer_active = streaming
        self.events: list[tuple[float, str, dict[str, object]]] = []
        self.actions: list[str] = []
        self._fails = fails

    def publish_event(self, kind: str, data: dict[str, object]) -> None:
        self.events.append((asyncio.get_running_loop().time(), kind, data))

    def kinds(self, kind: str) -> list[tuple[float, dict[str, object]]]:
        return [(t, data) for t, k, data in self.events if k == kind]

    async def hold_position_setpoint(self) -> SimpleNamespace:
        self.actions.append("hold")
        if self._fails:
            raise RuntimeError("no position yet")
        return SimpleNamespace(setpoint=PositionNed(1.0, 2.0, -3.0, 0.0))

    async def _command(self, name: str) -> CommandResult:
        self.actions.append(name)
        return CommandResult(name, 0, CommandOutcome.ACCEPTED, 0, 1.0)

    async def land(self) -> CommandResult:
        return await self._command("land")

    async def return_to_launch(self) -> CommandResult:
        return await self._command("rtl")

    async def set_mode(self, mode: str) -> CommandResult:
        return await self._command(f"mode {mode}")


class _Registry:
    def __init__(self, vehicle: _Vehicle) -> None:
        self._vehicle = vehicle

    def get(self, vehicle_id: int) -> _Vehicle | None:
        return self._vehicle if vehicle_id == self._vehicle.sysid else None


@contextlib.asynccontextmanager
async def _watched(
    vehicle: _Vehicle, action: OperatorLossAction = "hold"
) -> AsyncIterator[LeaseManager]:
    """Leases on the loop's clock (the default) with a running deadman."""
    leases = LeaseManager(ttl_s=2.0)
    deadman = Deadman(leases, cast("VehicleRegistry", _Registry(vehicle)), action)
    await deadman.start()
    try:
        yield leases
    finally:
        await deadman.stop()


@pytest.mark.looptime
async def test_lease_lapses_exactly_at_its_ttl_on_the_loop_clock() -> None:
    leases = LeaseManager(ttl_s=2.0)
    lease = leases.acquire(1, "alice", session="rest")
    await asyncio.sleep(1.999)
    assert leases.expire_due() == []
    assert leases.status(1) == ("alice", 0.001)
    await asyncio.sleep(0.001)
    assert leases.expire_due() == [lease]


@pytest.mark.looptime
async def test_expiry_while_streaming_applies_the_operator_loss_action() -> None:
    vehicle = _Vehicle()
    async with _watched(vehicle) as leases:
        lease = leases.acquire(1, "alice", session="rest")
        await asyncio.sleep(1.5)
        leases.renew(1, lease.lease_id)
        renewed_at = asyncio.get_running_loop().time()
        await lease.ended.wait()
        ended_at = asyncio.get_running_loop().time()
        await asyncio.sleep(0.001)  # virtual: lets the action task run

    # noticed by the first check at or after the TTL, never before it
    assert renewed_at + 2.0 <= ended_at < renewed_at + 2.0 + CHECK_PERIOD_S
    assert lease.end is LeaseEnd.EXPIRED
    assert [data["action"] for _, data in vehicle.kinds("lease")] == ["acquired", "expired"]
    assert vehicle.actions == ["hold"]
    ((_, event),) = vehicle.kinds("deadman")
    assert event == {
        "action": "hold",
        "cause": "expired",
        "ok": True,
        "setpoint": setpoint_as_dict(PositionNed(1.0, 2.0, -3.0, 0.0)),
    }


@pytest.mark.looptime
async def test_renewals_keep_the_lease_for_as_long_as_they_come() -> None:
    vehicle = _Vehicle()
    async with _watched(vehicle) as leases:
        lease = leases.acquire(1, "alice", session="ws")
        for _ in range(600):  # ten minutes of renewals every second
            await asyncio.sleep(1.0)
            leases.renew(1, lease.lease_id)

    assert lease.end is None
    assert vehicle.actions == []
    assert not vehicle.kinds("deadman")


@pytest.mark.looptime
@pytest.mark.parametrize(
    ("action", "taken"),
    [("land", "land"), ("rtl", "rtl"), ("hold-mode", "mode HOLD"), ("continue", None)],
)
async def test_each_operator_loss_policy_acts_once_when_the_socket_closes(
    action: OperatorLossAction, taken: str | None
) -> None:
    vehicle = _Vehicle()
    async with _watched(vehicle, action) as leases:
        lease = leases.acquire(1, "alice", session="ws")
        leases.release(1, lease.lease_id, LeaseEnd.CLOSED)
        await asyncio.sleep(0.001)

    assert vehicle.actions == ([taken] if taken else [])
    ((_, event),) = vehicle.kinds("deadman")
    assert event["action"] == action
    assert event["cause"] == "closed"
    assert event["ok"] is True


@pytest.mark.looptime
async def test_no_operator_loss_action_on_takeover_or_without_a_stream() -> None:
    streaming = _Vehicle()
    idle = _Vehicle(streaming=False)
    async with _watched(streaming) as leases:
        first = leases.acquire(1, "alice", session="ws")
        leases.acquire(1, "bob", session="rest", takeover=True)
        await asyncio.sleep(10.0)  # bob's lease lapses too, but there is still a stream
    async with _watched(idle) as leases:
        leases.acquire(1, "alice", session="rest")
        await asyncio.sleep(10.0)

    assert first.end is LeaseEnd.TAKEN_OVER
    assert [(data["holder"], data["action"]) for _, data in streaming.kinds("lease")] == [
        ("alice", "acquired"),
        ("alice", "taken_over"),
        ("bob", "acquired"),
        ("bob", "expired"),
    ]
    # one action, for bob's lapse; alice's takeover left a pilot at the controls
    assert [data["cause"] for _, data in streaming.kinds("deadman")] == ["expired"]
    assert idle.kinds("lease")[-1][1]["action"] == "expired"
    assert idle.actions == []
    assert not idle.kinds("deadman")


@pytest.mark.looptime
async def test_a_failed_operator_loss_action_is_announced_as_failed() -> None:
    vehicle = _Vehicle(fails=True)
    async with _watched(vehicle) as leases:
        lease = leases.acquire(1, "alice", session="rest")
        leases.release(1, lease.lease_id)
        await asyncio.sleep(0.001)

    ((_, event),) = vehicle.kinds("deadman")
    assert event == {
        "action": "hold",
        "cause": "released",
        "ok": False,
        "reason": "RuntimeError: no position yet",
    }
