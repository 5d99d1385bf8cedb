"""The setpoint sender process killed (-9) mid-flight, on the simulated vehicle in real time:
hovering in OFFBOARD, and flying sticks in POSCTL, with signing off and on. The vehicle never
leaves its mode; the largest gap between two setpoints (MANUAL_CONTROL) as a relay in front
of the vehicle receives them (kernel receive times) stays under what it can feel; the
server's sequence reaches it contiguous and signed frames pass its replay check; the API and
the server's own objects say which sender runs, its restarts and the fault, and a ``stream``
event tells the fault and the recovery. The app runs in the test's process, to look at those
objects; the vehicle and its relay in a process of their own (tests/faults/vehicle_apart.py).

A stopped sender (SIGSTOP) leaves the streams to the server's sender thread for longer, and
that thread needs the server's interpreter lock: those cases run against `skyhelm serve`,
in test_stream_sender_served.py, where the lock is not shared with the test's client."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from server.link import VehicleEvent
from server.link.stream.sender_supervisor import SenderSupervisor
from tests.api.conftest import Api, api_at
from tests.faults.sender_checks import (
    KILL_GAP_S,
    OFFBOARD_MODE,
    POSCTL_MODE,
    SETPOINT_ID,
    STICKS_ID,
    check_sequence,
    largest_gap,
    modes_since,
)
from tests.faults.vehicle_apart import Report, VehicleApart
from tests.waiting import wait_for


@dataclass
class Flight:
    api: Api
    vehicle: VehicleApart
    events: asyncio.Queue[VehicleEvent]
    # what the relay heard and the sim counted, taken when the flight ends
    final: Report | None = None

    async def mode_changes(self) -> int:
        """The sim's count of its mode changes (every one, not only those a HEARTBEAT
        shows)."""
        return (await self.vehicle.report_async()).mode_changes

    def ended(self) -> Report:
        assert self.final is not None
        return self.final


@contextlib.asynccontextmanager
async def flight(tmp_path: Path, *, signed: bool) -> AsyncIterator[Flight]:
    """The sim in real time behind a relay (a process of their own: tests/faults/
    vehicle_apart.py), SkyHelm in front, the lease taken."""
    vehicle = await asyncio.to_thread(VehicleApart, tmp_path / "sim" if signed else None)
    overrides: dict[str, Any] = {}
    if signed:
        overrides["signing_key_file"] = tmp_path / "keys" / "signing.key"
    try:
        async with api_at(f"udpout:127.0.0.1:{vehicle.relay_port}", None,
                          client_timeout_s=60.0, appear_within_s=20.0, **overrides) as api:
            await api.wait_ready()
            if signed:
                response = await api.client.post("/api/v1/signing", json={"action": "generate"})
                assert response.status_code == 200, response.text
                await api.wait_state(lambda s: s["link"]["signing"]["vehicles_signed"],
                                     10.0, "the vehicle signed")
            await api.take_control(ttl_s=60.0)
            f = Flight(api, vehicle, api.vehicle().subscribe_events())
            try:
                yield f
            finally:
                f.final = await vehicle.report_async()
    finally:
        await asyncio.to_thread(vehicle.close)


async def _hover_in_offboard(api: Api, vehicle: VehicleApart) -> None:
    assert (await api.control("arm")).status_code == 200
    assert (await api.control("takeoff", {"altitude_m": 3.0})).status_code == 200
    with vehicle.fast_forwarded():  # the climb; what is timed is the hover after it
        await api.wait_state(lambda s: s["position_ned"]["down_m"] < -2.5, 20.0,
                             "climb to 2.5 m")
    here = (await api.state())["position_ned"]
    start = await api.control("offboard/start", {"setpoint": {
        "type": "position_ned", "north_m": here["north_m"], "east_m": here["east_m"],
        "down_m": -3.0}})
    assert start.status_code == 200, start.text
    await api.wait_state(lambda s: s["mode"] == "OFFBOARD", 5.0, "OFFBOARD")


async def _fly_sticks_in_posctl(
    api: Api, vehicle: VehicleApart, feeder: list[asyncio.Task[None]]
) -> None:
    assert (await api.control("arm")).status_code == 200
    assert (await api.control("takeoff", {"altitude_m": 3.0})).status_code == 200
    with vehicle.fast_forwarded():
        await api.wait_state(lambda s: s["mode"] == "HOLD", 25.0, "takeoff done")

    async def feed() -> None:
        while True:  # the pilot's sticks at 10 Hz, a hover
            response = await api.client.put("/api/v1/vehicles/1/sticks",
                                            json={"throttle": 0.5}, headers=api.lease_headers)
            assert response.status_code == 200, response.text
            await asyncio.sleep(0.1)

    feeder.append(asyncio.create_task(feed()))
    # PX4 takes POSCTL only with manual control coming in
    await wait_for(lambda: api.vehicle().sticks_stats().sent >= 10, 10.0, "the sticks streaming")
    mode = await api.control("mode", {"mode": "POSCTL"})
    assert mode.status_code == 200, mode.text
    await api.wait_state(lambda s: s["mode"] == "POSCTL", 5.0, "POSCTL")


def _sender_pid(supervisor: SenderSupervisor) -> int:
    process = supervisor.current()
    assert process is not None
    assert process.pid is not None
    return process.pid


def _mode_changes_told(f: Flight, changed: int, watched_s: float) -> str:
    """A failure's account of mode changes: the vehicle's modes, and whether its own loop
    was starved (then the gap was not the stream's)."""
    return (f"the vehicle changed mode {changed} times; its modes "
            f"{modes_since(f.ended(), watched_s - 1.0)}, its loop up to "
            f"{f.ended().sim_late_s * 1000:.0f} ms late")


def _sender_log(caplog: pytest.LogCaptureFixture) -> list[tuple[float, str]]:
    return [(r.created, r.getMessage()[:320]) for r in caplog.records
            if "setpoint sender" in r.getMessage()]


async def _stream_events(queue: asyncio.Queue[VehicleEvent]) -> list[dict[str, Any]]:
    found = []
    while not queue.empty():
        event = queue.get_nowait()
        if event.kind == "stream" and "sender" in event.data:
            found.append(dict(event.data))
    return found


@pytest.mark.parametrize("signed", [False, True], ids=["unsigned", "signed"])
async def test_kill_9_of_the_sender_while_hovering_in_offboard(
    tmp_path: Path, supervisor: SenderSupervisor, signed: bool, caplog: pytest.LogCaptureFixture
) -> None:
    async with flight(tmp_path, signed=signed) as f:
        api = f.api
        await _hover_in_offboard(api, f.vehicle)
        assert (await api.client.get("/api/v1/vehicles/1/stream")).json()["sender"] == "process"
        rejected = (await f.vehicle.report_async()).signing_rejected
        await asyncio.sleep(1.0)
        changes = await f.mode_changes()
        watched_s = time.time()
        os.kill(_sender_pid(supervisor), signal.SIGKILL)
        await wait_for(lambda: api.vehicle().stream_stats().sender == "thread", 1.0,
                       "the thread takes over")
        during = (await api.client.get("/api/v1/vehicles/1/stream")).json()
        await wait_for(lambda: api.vehicle().stream_stats().sender == "process", 5.0,
                       "a restarted process takes over")
        await asyncio.sleep(1.0)
        after = (await api.client.get("/api/v1/vehicles/1/stream")).json()
        state = await api.state()
        ended_s = time.time()
        changed = await f.mode_changes() - changes
        events = await _stream_events(f.events)
    setpoints = [h for h in f.ended().since(watched_s - 0.5, SETPOINT_ID) if h.unix_s <= ended_s]
    gap_s, where = largest_gap(setpoints, watched_s, f.ended(), _sender_log(caplog))
    print(f"kill -9 in OFFBOARD ({'signed' if signed else 'unsigned'}): largest setpoint gap "
          f"at the vehicle {gap_s * 1000:.1f} ms over {len(setpoints)} setpoints")
    assert gap_s <= KILL_GAP_S, where
    assert changed == 0, _mode_changes_told(f, changed, watched_s)
    assert f.ended().signing_rejected == rejected, "frames the vehicle refused"
    check_sequence(f.ended(), watched_s - 0.5)
    assert modes_since(f.ended(), watched_s - 1.0) == {OFFBOARD_MODE}
    assert state["mode"] == "OFFBOARD"
    assert during["sender"] == "thread"
    assert during["active"] is True
    assert "SIGKILL" in during["sender_fault"]
    assert after["sender"] == "process"
    assert after["sender_restarts"] == 1, after["sender_fault"]
    assert after["active"] is True
    assert state["stream"]["sender"] == "process"
    assert [e["sender"] for e in events] == ["thread", "process"]
    assert "SIGKILL" in events[0]["fault"]
    assert events[1]["recovered"] is True


async def test_the_sender_killed_while_flying_sticks_in_posctl(
    tmp_path: Path, supervisor: SenderSupervisor, caplog: pytest.LogCaptureFixture
) -> None:
    feeder: list[asyncio.Task[None]] = []
    async with flight(tmp_path, signed=False) as f:
        api = f.api
        try:
            await _fly_sticks_in_posctl(api, f.vehicle, feeder)
            await asyncio.sleep(1.0)
            changes = await f.mode_changes()
            watched_s = time.time()
            os.kill(_sender_pid(supervisor), signal.SIGKILL)
            await wait_for(lambda: api.vehicle().sticks_stats().sender == "thread", 1.0,
                           "the thread takes over")
            during = (await api.client.get("/api/v1/vehicles/1/sticks")).json()
            await wait_for(lambda: api.vehicle().sticks_stats().sender == "process", 5.0,
                           "a restarted process takes over")
            await asyncio.sleep(1.0)
            after = (await api.client.get("/api/v1/vehicles/1/sticks")).json()
            state = await api.state()
            ended_s = time.time()
            changed = await f.mode_changes() - changes
        finally:
            for task in feeder:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
    sticks = [h for h in f.ended().since(watched_s - 0.5, STICKS_ID) if h.unix_s <= ended_s]
    gap_s, where = largest_gap(sticks, watched_s, f.ended(), _sender_log(caplog))
    rate_hz = (len(sticks) - 1) / (sticks[-1].unix_s - sticks[0].unix_s)
    print(f"kill of the sender in POSCTL: largest MANUAL_CONTROL gap at the vehicle "
          f"{gap_s * 1000:.1f} ms, {rate_hz:.1f} Hz over {len(sticks)} frames")
    assert gap_s <= KILL_GAP_S, where
    assert changed == 0, _mode_changes_told(f, changed, watched_s)
    assert 23.0 <= rate_hz <= 27.0
    check_sequence(f.ended(), watched_s - 0.5)
    assert modes_since(f.ended(), watched_s - 1.0) == {POSCTL_MODE}
    assert state["mode"] == "POSCTL"
    assert during["stream"]["sender"] == "thread"
    assert "SIGKILL" in during["stream"]["sender_fault"]
    assert after["stream"]["sender"] == "process"
    assert after["stream"]["sender_restarts"] == 1, after["stream"]["sender_fault"]
