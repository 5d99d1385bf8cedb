"""The live-input deadman and the audit log, on the event loop's virtual clock: a silent live
input brakes, anything else is never cancelled by waiting; lease loss keeps its own action;
every control and deadman event lands in the audit file and is read back after a restart."""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

import pytest

from server.control.audit import AUDIT_FILE_NAME, AuditLog
from server.control.deadman import CHECK_PERIOD_S, Brake, Deadman
from server.control.lease import Lease, LeaseEnd, LeaseManager
from server.control.registry import VehicleRegistry
from server.http.schemas import setpoint_as_dict
from server.link import PositionNed, SentSetpoint, VelocityNed

TIMEOUT_S = 1.0


class _Vehicle:
    """What the deadman uses of a vehicle: the streamed setpoint, events, the hold."""

    sysid = 1
    sticks_active = False

    def __init__(self) -> None:
        self.streamer_active = True
        self.setpoint: object = None
        self.events: list[tuple[float, str, dict[str, object]]] = []
        self.actions: list[str] = []

    def fly(self, setpoint: object) -> None:
        """A setpoint accepted and streamed, as set_setpoint leaves it."""
        self.setpoint = setpoint

    def publish_event(self, kind: str, data: dict[str, object]) -> None:
        self.events.append((asyncio.get_running_loop().time(), kind, data))

    def deadman(self) -> list[tuple[float, dict[str, object]]]:
        return [(t, data) for t, kind, data in self.events if kind == "deadman"]

    async def hold_position_setpoint(self) -> SimpleNamespace:
        self.actions.append("hold")
        return SimpleNamespace(setpoint=PositionNed(1.0, 2.0, -3.0, 0.0))


class _Registry:
    def __init__(self, vehicle: _Vehicle) -> None:
        self.vehicle = vehicle

    def get(self, vehicle_id: int) -> _Vehicle | None:
        return self.vehicle if vehicle_id == 1 else None


async def _brake(vehicle: Any) -> SentSetpoint:
    vehicle.actions.append("brake")
    vehicle.fly(VelocityNed(0.0, 0.0, 0.0))
    return cast("SentSetpoint", SimpleNamespace(setpoint=VelocityNed(0.0, 0.0, 0.0)))


@dataclass
class _Flight:
    vehicle: _Vehicle
    leases: LeaseManager
    deadman: Deadman
    lease: Lease
    fed_at: float


@contextlib.asynccontextmanager
async def _keys_flying(
    audit: AuditLog | None = None, brake: Brake = _brake
) -> AsyncIterator[_Flight]:
    """A pilot on the keys: holding the lease, flying a live velocity just fed, the
    deadman running."""
    vehicle = _Vehicle()
    leases = LeaseManager(120.0, min_ttl_s=1.0, max_ttl_s=600.0)
    registry = cast("VehicleRegistry", _Registry(vehicle))
    deadman = Deadman(leases, registry, "hold", live_timeout_s=TIMEOUT_S, audit=audit, brake=brake)
    await deadman.start()
    try:
        lease = leases.acquire(1, "pilot · keys", session="ws")
        vehicle.fly(VelocityNed(2.0, 0.0, 0.0))
        deadman.watch_live(1, live=True)
        yield _Flight(vehicle, leases, deadman, lease, asyncio.get_running_loop().time())
    finally:
        await deadman.stop()


@pytest.mark.looptime
async def test_a_silent_live_input_brakes_after_the_timeout() -> None:
    async with _keys_flying() as flight:
        await asyncio.sleep(TIMEOUT_S + 2 * CHECK_PERIOD_S)

    ((braked_at, event),) = flight.vehicle.deadman()
    assert flight.fed_at + TIMEOUT_S <= braked_at < flight.fed_at + TIMEOUT_S + CHECK_PERIOD_S
    assert flight.vehicle.actions == ["brake"]
    assert event == {
        "action": "brake",
        "cause": "live_timeout",
        "timeout_s": TIMEOUT_S,
        "ok": True,
        "setpoint": setpoint_as_dict(VelocityNed(0.0, 0.0, 0.0)),
    }
    assert not flight.deadman.live_watched(1)


@pytest.mark.looptime
async def test_a_live_input_fed_in_time_never_brakes() -> None:
    async with _keys_flying() as flight:
        for step in range(100):  # 20 s of key repeats every 0.2 s
            await asyncio.sleep(0.2)
            flight.vehicle.fly(VelocityNed(1.0 + step % 2, 0.0, 0.0))
            flight.deadman.watch_live(1, live=True)
        assert flight.deadman.live_watched(1)
    assert flight.vehicle.actions == []


@pytest.mark.looptime
async def test_a_script_setpoint_is_never_cancelled_by_waiting() -> None:
    async with _keys_flying() as flight:
        # then a position setpoint, not live, and a minute's wait
        flight.vehicle.fly(PositionNed(10.0, 0.0, -5.0, None))
        flight.deadman.watch_live(1, live=False)
        await asyncio.sleep(60.0)
    assert flight.vehicle.actions == []
    assert not flight.vehicle.deadman()


@pytest.mark.looptime
async def test_a_setpoint_replacing_the_live_one_unannounced_is_not_braked() -> None:
    async with _keys_flying() as flight:
        vehicle = flight.vehicle
        vehicle.fly(PositionNed(0.0, 0.0, -5.0, None))  # e.g. an intent's position hold
        await asyncio.sleep(5.0)
        vehicle.fly(VelocityNed(2.0, 0.0, 0.0))
        vehicle.streamer_active = False  # and nothing is braked once the stream stopped
        flight.deadman.feed_live(1)
        await asyncio.sleep(5.0)
    assert vehicle.actions == []


@pytest.mark.looptime
async def test_lease_loss_runs_the_operator_loss_action_not_the_brake() -> None:
    async with _keys_flying() as flight:
        flight.leases.release(1, flight.lease.lease_id, LeaseEnd.CLOSED)
        await asyncio.sleep(5.0)
    assert flight.vehicle.actions == ["hold"]
    assert [data["cause"] for _, data in flight.vehicle.deadman()] == ["closed"]


@pytest.mark.looptime
async def test_a_takeover_keeps_the_live_watch_for_the_new_holder() -> None:
    async with _keys_flying() as flight:
        flight.leases.acquire(1, "pilot · tab 2", session="ws", takeover=True)
        await asyncio.sleep(TIMEOUT_S + 2 * CHECK_PERIOD_S)
    # the old holder's keys went quiet and the new holder sent nothing live: brake
    assert flight.vehicle.actions == ["brake"]


@pytest.mark.looptime
async def test_a_failed_brake_is_announced_as_failed() -> None:
    async def no_position(_: Any) -> SentSetpoint:
        raise RuntimeError("no local position yet")

    async with _keys_flying(brake=no_position) as flight:
        await asyncio.sleep(TIMEOUT_S + 2 * CHECK_PERIOD_S)
    ((_, event),) = flight.vehicle.deadman()
    assert event["ok"] is False
    assert event["reason"] == "RuntimeError: no local position yet"


# ---- audit --------------------------------------------------------------------------------


class _WallClock:
    def __init__(self) -> None:
        self.now = 1_764_000_000.0

    def __call__(self) -> float:
        self.now += 1.0
        return self.now


@pytest.mark.looptime
async def test_control_and_deadman_events_are_audited_and_survive_a_restart(
    tmp_path: Path,
) -> None:
    audit = AuditLog(tmp_path, wall_clock=_WallClock())
    async with _keys_flying(audit) as flight:
        await asyncio.sleep(TIMEOUT_S + 2 * CHECK_PERIOD_S)
        flight.leases.release(1, flight.lease.lease_id)
        await asyncio.sleep(0.1)

    lines = (tmp_path / AUDIT_FILE_NAME).read_text().splitlines()
    written = [json.loads(line) for line in lines]
    assert [(e["kind"], e["data"]["action"]) for e in written] == [
        ("control", "acquired"),
        ("deadman", "brake"),
        ("control", "released"),
        ("deadman", "hold"),
    ]
    assert written[0] == {
        "time_unix_s": 1_764_000_001.0,
        "vehicle": 1,
        "kind": "control",
        "data": {
            "action": "acquired",
            "session": "ws",
            "holder": "pilot · keys",
            "previous_holder": None,
            "since_s": 0.0,
            "ttl_s": 120.0,
        },
    }
    # a restarted server reads the file's tail back
    restarted = AuditLog(tmp_path)
    assert restarted.load() == 4
    assert restarted.entries(1, 100) == written
    assert restarted.entries(2, 100) == []
    assert restarted.entries(None, 2) == written[-2:]


def test_the_audit_keeps_the_newest_entries_and_skips_broken_lines(tmp_path: Path) -> None:
    path = tmp_path / AUDIT_FILE_NAME
    path.write_text(
        "".join(json.dumps({"vehicle": 1, "kind": "control", "n": n}) + "\n" for n in range(10))
        + "not json\n[1, 2]\n"
    )
    audit = AuditLog(tmp_path, memory=4)
    # the last four lines are read; two of them are JSON objects
    assert audit.load() == 2
    assert [e["n"] for e in audit.entries()] == [8, 9]


def test_the_audit_writes_non_finite_numbers_as_null(tmp_path: Path) -> None:
    audit = AuditLog(tmp_path)
    audit.append(1, "deadman", {"setpoint": {"vn_m_s": math.nan}, "limits": [math.inf, 1.0]})
    (entry,) = [json.loads(line) for line in (tmp_path / AUDIT_FILE_NAME).read_text().splitlines()]
    assert entry["data"] == {"setpoint": {"vn_m_s": None}, "limits": [None, 1.0]}


def test_without_a_log_dir_the_audit_is_kept_in_memory() -> None:
    audit = AuditLog(None)
    audit.append(3, "control", {"action": "acquired"})
    assert audit.load() == 0
    assert [e["data"] for e in audit.entries(3)] == [{"action": "acquired"}]
