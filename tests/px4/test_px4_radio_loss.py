"""Real PX4 v1.16 SITL hovering in OFFBOARD on SkyHelm's stream through 20 % loss each way
for minutes, after HEARTBEAT-only drops of 3.6 s: never judged lost, never a failsafe, every
command answered with the truth or 504. Opt-in twice: `make test-px4` and
SKYHELM_PX4_SOAK_MINUTES (10 for the figure in docs/RELIABILITY.md)."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import os
import time
from collections.abc import Callable
from typing import Any

import pytest

from server.link import VehicleEvent
from tests.api.conftest import Api
from tests.px4.conftest import Px4Process
from tests.px4.test_px4_linkloss import Tap, _fly_offboard, app_via, proxied
from tests.waiting import wait_for
from tools.faultproxy import MAVLINK_MSG_ID_HEARTBEAT, Faults

pytestmark = pytest.mark.px4

LOSS_PCT = 20.0
HEARTBEAT_DROPS = 3
HEARTBEAT_DROP_S = 3.6
COMMAND_EVERY_S = 10.0


def _soak_minutes() -> float:
    minutes = os.environ.get("SKYHELM_PX4_SOAK_MINUTES")
    if not minutes:
        pytest.skip("set SKYHELM_PX4_SOAK_MINUTES (e.g. 10) for the PX4 radio soak")
    return float(minutes)


async def _checked_command(api: Api, sysid: int, which: int,
                           outcomes: dict[str, int]) -> None:
    """One command whose answer is checked against PX4's state: its outcome counted."""
    path, truth = (("mode", lambda s: s["mode"] == "OFFBOARD") if which % 2 == 0
                   else ("arm", lambda s: s["armed"] is True))
    body = {"mode": "OFFBOARD"} if path == "mode" else None
    answer = await api.control(path, body, vehicle_id=sysid)
    if answer.status_code == 504:
        outcome = "504"
    elif answer.status_code == 200 and truth(await api.state(sysid)):
        outcome = "answered and true"
    else:
        outcome = f"wrong: {answer.status_code} {answer.text[:120]}"
    outcomes[outcome] = outcomes.get(outcome, 0) + 1


async def _hold(api: Api, sysid: int, tap: Tap, seconds: float,
                lost: Callable[[], int], outcomes: dict[str, int]) -> None:
    """Hover for seconds, a checked command every COMMAND_EVERY_S; fails at the first lost
    verdict or PX4 mode other than OFFBOARD."""
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    next_command = loop.time() + COMMAND_EVERY_S
    which = 0
    while loop.time() < end:
        assert lost() == 0, "SkyHelm judged PX4 lost"
        assert tap.mode() == "OFFBOARD", (
            f"PX4 left OFFBOARD: {tap.modes[-3:]}; largest gaps of the setpoints handed to "
            f"PX4 in the last 10 s: {_largest_gaps(tap.setpoints)}")
        if loop.time() >= next_command:
            await _checked_command(api, sysid, which, outcomes)
            which += 1
            next_command += COMMAND_EVERY_S
        with contextlib.suppress(Exception):  # the lease is renewed; a lost renewal is no finding
            await api.client.put(f"/api/v1/vehicles/{sysid}/control", headers=api.lease_headers)
        await asyncio.sleep(0.5)


@pytest.mark.timeout(3600)  # as long as SKYHELM_PX4_SOAK_MINUTES asks, up to most of an hour
async def test_px4_hovers_through_20pct_loss_and_heartbeat_drops(px4_process: Px4Process) -> None:
    minutes = _soak_minutes()
    sitl = px4_process.sitl
    sent_to_proxy: list[float] = []

    def count_sent(direction: str, frame: bytes) -> None:
        if direction == "to_vehicle" and len(frame) >= 10 and frame[0] == 0xFD \
                and int.from_bytes(frame[7:10], "little") == 84:  # SET_POSITION_TARGET_LOCAL_NED
            sent_to_proxy.append(time.monotonic())

    async with proxied(sitl) as (proxy, tap), app_via(proxy, sitl.sysid) as api:
        proxy.add_tap(count_sent, arriving=True)
        await _fly_offboard(api)
        events = api.vehicle(sitl.sysid).subscribe_events(4096)
        seen: list[VehicleEvent] = []

        def lost() -> int:
            while not events.empty():
                seen.append(events.get_nowait())
            return sum(1 for e in seen if e.kind == "connection" and not e.data["connected"])

        outcomes: dict[str, int] = {}
        for _ in range(HEARTBEAT_DROPS):
            proxy.drop_messages({MAVLINK_MSG_ID_HEARTBEAT}, HEARTBEAT_DROP_S, "to_server")
            await _hold(api, sitl.sysid, tap, HEARTBEAT_DROP_S + 3.0, lost, outcomes)
        warned = [e.data["causes"] for e in seen if e.kind == "link_quality"]
        assert any("heartbeat" in causes for causes in warned), warned

        setpoints_from, sent_from = len(tap.setpoints), len(sent_to_proxy)
        proxy.configure(Faults(loss_pct=LOSS_PCT))
        started = time.monotonic()
        await _hold(api, sitl.sysid, tap, minutes * 60.0, lost, outcomes)
        quality: dict[str, Any] = (await api.state(sitl.sysid))["link_quality"]
        proxy.configure(Faults())
        received = len(tap.setpoints) - setpoints_from
        sent = len(sent_to_proxy) - sent_from
        held_s = time.monotonic() - started
        await wait_for(lambda: tap.mode() == "OFFBOARD", 5.0, "still OFFBOARD")
    wrong = {k: v for k, v in outcomes.items() if k.startswith("wrong")}
    print(f"\nPX4 {minutes:g} min at {LOSS_PCT:g}% loss each way after {HEARTBEAT_DROPS} "
          f"HEARTBEAT-only drops of {HEARTBEAT_DROP_S} s: lost verdicts {lost()}, PX4 left "
          f"OFFBOARD 0 times, commands {outcomes}, setpoints sent {sent} / received by PX4 "
          f"{received} ({100 * received / max(1, sent):.1f}%, {received / held_s:.1f} Hz), "
          f"link quality at the end {quality}; proxy {proxy.stats()}")
    assert not wrong, wrong
    assert lost() == 0


def _largest_gaps(times: list[float]) -> list[tuple[float, float]]:
    """(seconds before now, gap) of the three longest gaps in the last 10 s of times."""
    now = time.monotonic()
    recent = [t for t in times if now - t < 10.0]
    gaps = [(round(now - b, 2), round(b - a, 3)) for a, b in itertools.pairwise(recent)]
    return sorted(gaps, key=lambda g: -g[1])[:3]
