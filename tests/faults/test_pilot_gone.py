"""The pilot's browser goes away while flying a live velocity over the control socket:

- the tab is killed (the process SIGKILLed: the TCP connection ends with no close frame),
- the laptop falls asleep (the process SIGSTOPped: the socket stays open and goes silent).

Either way the deadman must stop the vehicle within its timeout. The times are measured from
the kill or the freeze to the deadman event on an observer's telemetry socket, and to the
vehicle below 0.3 m/s; they are printed (run with -s) and listed in docs/RELIABILITY.md."""

from __future__ import annotations

import asyncio
import contextlib
import math
import signal
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect

from tests.api.conftest import OBSERVER, api_for, sim_cluster
from tests.api.test_ws import TTL_S, Served, receive_until
from tests.serving import uvicorn_serving
from tests.waiting import eventually

ROOT = Path(__file__).resolve().parents[2]
DEADMAN_S = 0.5
LEASE_TTL_S = 2.0
INPUT_RATE_HZ = 20.0
FLY_NORTH_M_S = 2.0
STOPPED_M_S = 0.3
# how late a deadman may be on a loaded machine before the test calls it a failure
LATE_S = 1.0
HOLD_HERE = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -4.0}


def _speed(state: dict[str, Any]) -> float:
    velocity = state["velocity_ned"]
    return math.hypot(velocity["north_m_s"], velocity["east_m_s"])


@pytest.fixture
async def quad() -> AsyncIterator[Served]:
    # the sim in real time: the times to stop are real seconds, and a loaded machine does
    # not starve a sim running 8x faster in the same process
    async with (
        sim_cluster("quad", speed=1.0) as sim,
        api_for(sim, lease_ttl_s=TTL_S, deadman_timeout_s=DEADMAN_S) as api,
    ):
        await api.wait_ready()
        async with uvicorn_serving(api.app) as host:
            s = Served(api, host)
            await _hover_in_offboard(s)
            yield s


async def _hover_in_offboard(s: Served) -> None:
    """A script arms, climbs, enters OFFBOARD holding, then gives control back."""
    api = s.api
    # the set-up's own lease outlives a busy machine's gaps between its calls (the server's
    # 1 s TTL is for the pilots under test)
    await api.take_control(ttl_s=60.0)
    assert (await api.control("arm")).status_code == 200
    assert (await api.control("takeoff", {"altitude_m": 4.0})).status_code == 200
    assert api.sim is not None
    with api.sim.fast_forwarded():  # the climb; what is timed comes after it
        await api.wait_state(lambda st: st["position_ned"]["down_m"] < -3.0, 20.0, "climb")
    started = await api.control("offboard/start", {"setpoint": HOLD_HERE})
    assert started.status_code == 200, started.text
    released = await api.client.delete("/api/v1/vehicles/1/control", headers=api.lease_headers)
    assert released.status_code == 204, released.text
    api.lease_headers = {}


@contextlib.asynccontextmanager
async def tab_flying_north(s: Served) -> AsyncIterator[asyncio.subprocess.Process]:
    """A pilot's tab in its own process, flying north at FLY_NORTH_M_S on live input."""
    url = s.url("control", vehicle=1, client_name="tab", ttl_s=LEASE_TTL_S)
    tab = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "tests.faults.ws_pilot", url, str(FLY_NORTH_M_S),
        str(INPUT_RATE_HZ), cwd=ROOT, stdout=asyncio.subprocess.PIPE,
    )
    try:
        assert tab.stdout is not None
        while (line := await asyncio.wait_for(tab.stdout.readline(), 30.0)) != b"flying\n":
            assert line.startswith(b"sent "), line

        async def at_speed() -> bool:
            return _speed(await s.api.state()) > FLY_NORTH_M_S * 0.8

        await eventually(at_speed, 20.0, "the tab's velocity to be flown", poll_s=0.05)
        yield tab
    finally:
        if tab.returncode is None:
            tab.send_signal(signal.SIGCONT)
            tab.kill()
            await tab.wait()


async def _last_sent_s(tab: asyncio.subprocess.Process) -> float:
    """When the frozen tab's last input went out (its ``sent`` lines written before the
    freeze; the monotonic clock is the machine's, so this test's too)."""
    assert tab.stdout is not None
    last = None
    with contextlib.suppress(TimeoutError):
        while line := await asyncio.wait_for(tab.stdout.readline(), 0.2):
            if line.startswith(b"sent "):
                last = float(line.split()[1])
    assert last is not None, "the tab wrote no send"
    return last


async def _deadman_event(telemetry: ClientConnection, cause: str) -> dict[str, Any]:
    while True:
        event = await receive_until(telemetry, {"type": "event", "kind": "deadman"}, 15.0)
        if event["data"].get("cause") == cause:
            data: dict[str, Any] = event["data"]
            return data


async def _seconds_to_stop(s: Served, since: float) -> float:
    async def stopped() -> bool:
        return _speed(await s.api.state()) < STOPPED_M_S

    await eventually(stopped, 15.0, "the vehicle to stop", poll_s=0.02)
    return time.monotonic() - since


async def test_a_killed_tab_is_noticed_at_once_and_the_vehicle_holds(quad: Served) -> None:
    async with (
        connect(quad.url("telemetry", token=OBSERVER, vehicle=1, rate_hz=2)) as telemetry,
        tab_flying_north(quad) as tab,
    ):
        tab.kill()  # no close frame: the kernel just ends the TCP connection
        killed_at = time.monotonic()
        event = await _deadman_event(telemetry, "closed")
        detected_s = time.monotonic() - killed_at
        stopped_s = await _seconds_to_stop(quad, killed_at)
    state = await quad.api.state()
    print(f"\ntab killed while flying {FLY_NORTH_M_S} m/s live: deadman ({event['action']}, "
          f"cause {event['cause']}) after {1000 * detected_s:.0f} ms, vehicle below "
          f"{STOPPED_M_S} m/s after {stopped_s:.2f} s; lease holder now {state['lease']['holder']}")
    assert event["action"] == "hold"
    assert event["ok"] is True
    assert detected_s <= LATE_S  # a closed socket ends the lease at once
    assert state["mode"] == "OFFBOARD"  # holding on the server's stream, not failsafing
    assert state["lease"]["holder"] is None


async def test_a_sleeping_laptop_brakes_after_the_deadman_then_loses_the_lease(
    quad: Served,
) -> None:
    async with (
        connect(quad.url("telemetry", token=OBSERVER, vehicle=1, rate_hz=2)) as telemetry,
        tab_flying_north(quad) as tab,
    ):
        tab.send_signal(signal.SIGSTOP)  # frozen: the socket stays open, nothing is sent
        frozen_at = time.monotonic()
        brake = await _deadman_event(telemetry, "live_timeout")
        braked_at = time.monotonic()
        braked_s = braked_at - frozen_at
        # the brake keeps the lease (asked at once: on a loaded machine the stop itself
        # may take longer than the lease's TTL)
        assert (await quad.api.state())["lease"]["holder"] == "pilot · tab"
        stopped_s = await _seconds_to_stop(quad, frozen_at)
        lapsed = await _deadman_event(telemetry, "expired")
        lapsed_at = time.monotonic()
        lapsed_s = lapsed_at - frozen_at
        last_sent_s = await _last_sent_s(tab)
    print(f"\nlaptop asleep while flying {FLY_NORTH_M_S} m/s live: brake after "
          f"{1000 * braked_s:.0f} ms (deadman_timeout_s {DEADMAN_S}), vehicle below "
          f"{STOPPED_M_S} m/s after {stopped_s:.2f} s, lease lapsed after {lapsed_s:.2f} s "
          f"(ttl_s {LEASE_TTL_S}) -> {lapsed['action']}")
    # never before its time after the tab's last input (timed from that send: on a busy
    # machine the tab may have had no core for a while before the freeze), and at most
    # LATE_S after it counting from the freeze
    assert braked_at - last_sent_s >= DEADMAN_S
    assert braked_s <= DEADMAN_S + LATE_S
    assert brake["action"] == "brake"
    assert brake["ok"] is True
    assert lapsed_at - last_sent_s >= LEASE_TTL_S
    assert lapsed_s <= LEASE_TTL_S + LATE_S
    assert lapsed["action"] == "hold"
    state = await quad.api.state()
    assert state["mode"] == "OFFBOARD"
    assert _speed(state) < STOPPED_M_S
