"""The link-loss scenarios of tests/faults/ against real PX4 v1.16 SITL (SIH quad), with the
fault proxy between SkyHelm and PX4: a 5 s partition in OFFBOARD, the server killed with
SIGKILL in OFFBOARD, and PX4 restarted (a reboot). Opt-in: `make test-px4`.

PX4's API link sends to the port the kit's run.sh names; the proxy binds that port (its
vehicle-facing side) and SkyHelm connects to the proxy's other side. Each test starts a
fresh PX4 instance; the figures are printed (-s) and recorded in docs/RELIABILITY.md.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.modes import name_from_custom_mode
from tests.api.conftest import Api, api_for
from tests.faults.linkloss_rig import read_tlog, rest_state
from tests.px4.conftest import Px4Process, Px4Sitl
from tests.serve_process import skyhelm_serve
from tests.waiting import eventually, holds_for, wait_for
from tools.faultproxy import FaultProxy

pytestmark = pytest.mark.px4

PARTITION_S = 5.0
CLIMB_TO = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -5.0}
LIVE_FIELDS = {"mode", "armed", "position_ned", "global_position", "attitude"}


class Tap:
    """What the proxy passed on: PX4's modes (HEARTBEAT) and SkyHelm's setpoints/commands."""

    def __init__(self) -> None:
        self._parsers = {d: mavlink.MAVLink(None) for d in ("to_vehicle", "to_server")}
        self.modes: list[tuple[float, str]] = []
        self.setpoints: list[float] = []
        self.commands: list[tuple[float, int]] = []
        self.param_reads: list[tuple[float, str]] = []

    def __call__(self, direction: str, payload: bytes) -> None:
        now = time.monotonic()
        for msg in self._parsers[direction].parse_buffer(payload) or []:
            kind = msg.get_type()
            if kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
                self.modes.append((now, name_from_custom_mode(msg.custom_mode)))
            elif kind == "SET_POSITION_TARGET_LOCAL_NED":
                self.setpoints.append(now)
            elif kind == "COMMAND_LONG":
                self.commands.append((now, msg.command))
            elif kind == "PARAM_REQUEST_READ":
                self.param_reads.append((now, msg.param_id))

    def mode(self) -> str | None:
        return self.modes[-1][1] if self.modes else None


@contextlib.asynccontextmanager
async def proxied(sitl: Px4Sitl) -> AsyncIterator[tuple[FaultProxy, Tap]]:
    tap = Tap()
    async with FaultProxy(vehicle_listen=(sitl.api_host, sitl.api_port), seed=13) as proxy:
        proxy.add_tap(tap)
        yield proxy, tap


def _url(proxy: FaultProxy) -> str:
    return f"udpout:127.0.0.1:{proxy.server_facing_address[1]}"


@contextlib.asynccontextmanager
async def app_via(proxy: FaultProxy, sysid: int) -> AsyncIterator[Api]:
    async with api_for(None, connect=[_url(proxy)]) as api:
        await wait_for(lambda: api.app.state.api.registry.get(sysid) is not None, 30.0,
                       "PX4 discovered")
        api.default_vehicle = sysid
        await api.wait_state(
            lambda s: s["global"] is not None and s["home"] is not None, 60.0, "PX4 ready"
        )
        yield api


async def _fly_offboard(api: Api) -> None:
    await api.take_control()
    # PX4 SITL passes its pre-arm checks some seconds after boot; it may still refuse once
    await api.wait_state(lambda s: bool(s["ready_to_arm"]), 60.0, "ready to arm")

    async def armed() -> bool:
        answer = await api.control("arm")
        assert answer.status_code in (200, 409), answer.text
        return answer.status_code == 200

    await eventually(armed, 30.0, "armed", poll_s=0.5)
    start = await api.control("offboard/start", {"setpoint": CLIMB_TO})
    assert start.status_code == 200, start.text
    await api.wait_state(lambda s: s["position_ned"]["down_m"] < -4.0, 30.0, "climb to 4 m")


async def test_px4_partition_in_offboard(px4_process: Px4Process) -> None:
    sitl = px4_process.sitl
    async with proxied(sitl) as (proxy, tap), app_via(proxy, sitl.sysid) as api:
        await _fly_offboard(api)
        holder = (await api.state())["lease"]["holder"]
        events = api.vehicle(sitl.sysid).subscribe_events(1024)

        cut = time.monotonic()
        proxy.partition(PARTITION_S)
        lost = await api.wait_state(lambda s: not s["connected"], 5.0, "loss shown", renew=False)
        detect_s = time.monotonic() - cut
        assert detect_s < 3.0
        assert lost["stream"]["active"] is False
        assert set(lost["stale"]) >= LIVE_FIELDS

        seen: list[dict[str, Any]] = []

        async def back() -> dict[str, Any] | None:
            state = await rest_state(api.client, sitl.sysid)
            if state["connected"]:
                seen.append(state)
            return state if state["connected"] else None

        await eventually(back, PARTITION_S + 5.0, "the link back", poll_s=0.01)
        back_at = time.monotonic()
        # PX4 sent HEARTBEATs into the partition too: the proxy's tap saw none of those,
        # but the first one after the heal tells the mode PX4 flew during the cut

        async def fresh() -> dict[str, Any] | None:
            state = await rest_state(api.client, sitl.sysid)
            seen.append(state)
            return state if not (LIVE_FIELDS & set(state["stale"])) else None

        state = await eventually(fresh, 5.0, "fresh state", poll_s=0.01)
        fresh_s = time.monotonic() - back_at
        assert all(s["mode"] != "OFFBOARD" for s in seen), [s["mode"] for s in seen]
        assert state["user_mode"] == "OFFBOARD"
        failsafe_mode = state["mode"]
        assert fresh_s < 1.0

        report = await _next_event(events, "link_restored", 5.0)
        assert report["failsafe"] is True
        assert report["mode_before"] == "OFFBOARD"
        heal_s = time.monotonic()
        await holds_for(
            lambda: not any(t >= heal_s for t in tap.setpoints) and tap.mode() != "OFFBOARD",
            2.0, "PX4 not back in OFFBOARD: nothing streamed after the heal",
        )
        after = await api.state()
        assert after["lease"]["holder"] == holder
        assert after["stream"]["active"] is False

        again = await api.control("setpoint", CLIMB_TO)
        assert again.status_code == 200, again.text
        await api.wait_state(lambda s: s["mode"] == "OFFBOARD", 10.0, "OFFBOARD on a setpoint")
    print(f"\nPX4 partition {PARTITION_S:.1f} s in OFFBOARD: lost shown after {detect_s:.2f} s, "
          f"fresh {fresh_s:.2f} s after the link came back, PX4 flew {failsafe_mode}; "
          f"report: {report['text']}")


async def _next_event(queue: asyncio.Queue[Any], kind: str, timeout_s: float) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while True:
        event = await asyncio.wait_for(queue.get(), max(0.01, deadline - time.monotonic()))
        if event.kind == kind:
            data: dict[str, Any] = dict(event.data)
            return data


async def test_px4_server_sigkill_in_offboard(px4_process: Px4Process, tmp_path: Path) -> None:
    sitl = px4_process.sitl
    async with proxied(sitl) as (proxy, tap):
        first = tmp_path / "first"
        first.mkdir()
        with skyhelm_serve(first, "--connect", _url(proxy), "--no-scene") as served:
            async with _client(served.api, served.pilot_token) as client:
                await _fly_offboard_http(client, sitl.sysid)
            assert served.process is not None
            killed_at = time.monotonic()
            served.process.send_signal(signal.SIGKILL)
            served.process.wait(timeout=10)
        await wait_for(lambda: tap.mode() not in (None, "OFFBOARD"), 10.0, "PX4's failsafe")
        failsafe_s = next(t for t, m in tap.modes if t >= killed_at and m != "OFFBOARD") - killed_at
        failsafe_mode = tap.mode()

        second = tmp_path / "second"
        second.mkdir()
        with skyhelm_serve(second, "--connect", _url(proxy), "--no-scene") as served:
            restarted = time.monotonic()  # serving: from here it looks for the vehicle
            async with _client(served.api, served.pilot_token) as client:

                async def found() -> dict[str, Any] | None:
                    response = await client.get(f"/vehicles/{sitl.sysid}")
                    if response.status_code != 200:
                        return None
                    state: dict[str, Any] = response.json()
                    return state if not state["stale"] else None

                state = await eventually(found, 30.0, "PX4 found again")
                found_s = time.monotonic() - restarted
                assert state["mode"] == tap.mode(), [(round(t - killed_at, 2), m)
                                                     for t, m in tap.modes if t >= killed_at]
                assert state["mode"] != "OFFBOARD"
                assert state["stream"]["active"] is False
                since = time.monotonic()
                await holds_for(lambda: not any(t >= since for t in tap.setpoints), 2.0,
                                "nothing streamed by the new server")
        tlogs = list(first.glob("*.tlog"))
        _, messages, records = read_tlog(first)
        assert len(tlogs) == 1
        assert messages == records
        assert messages > 100
    print(f"\nPX4 server SIGKILL in OFFBOARD: PX4 left OFFBOARD for {failsafe_mode} "
          f"{failsafe_s:.2f} s after the kill; restarted server found it in {state['mode']} "
          f"after {found_s:.2f} s; tlog {messages} messages readable")


def _client(base: str, token: str) -> httpx.AsyncClient:
    return httpx.AsyncClient(base_url=base, headers={"Authorization": f"Bearer {token}"},
                             timeout=30.0)


async def _fly_offboard_http(client: httpx.AsyncClient, sysid: int) -> None:
    async def ready() -> bool:
        response = await client.get(f"/vehicles/{sysid}")
        if response.status_code != 200:
            return False
        state = response.json()
        return state["home"] is not None and state["global"] is not None

    await eventually(ready, 60.0, "PX4 ready on the server", poll_s=0.2)
    taken = await client.post(f"/vehicles/{sysid}/control", json={})
    assert taken.status_code == 200, taken.text
    lease = {"X-Lease-Id": taken.json()["lease_id"]}

    async def armed() -> bool:
        await client.put(f"/vehicles/{sysid}/control", headers=lease)
        state = (await client.get(f"/vehicles/{sysid}")).json()
        if not state["ready_to_arm"]:
            return False
        answer = await client.post(f"/vehicles/{sysid}/arm", json={}, headers=lease)
        assert answer.status_code in (200, 409), answer.text
        return answer.status_code == 200

    await eventually(armed, 60.0, "armed", poll_s=0.5)
    start = await client.post(f"/vehicles/{sysid}/offboard/start", json={"setpoint": CLIMB_TO},
                              headers=lease)
    assert start.status_code == 200, start.text

    async def climbed() -> bool:
        await client.put(f"/vehicles/{sysid}/control", headers=lease)
        response = await client.get(f"/vehicles/{sysid}")
        return bool(response.json()["position_ned"]["down_m"] < -4.0)

    await eventually(climbed, 30.0, "climb to 4 m", poll_s=0.2)


async def test_px4_restart_is_noticed_as_a_reboot(px4_process: Px4Process) -> None:
    sitl = px4_process.sitl
    async with proxied(sitl) as (proxy, tap), app_via(proxy, sitl.sysid) as api:
        vehicle = api.vehicle(sitl.sysid)
        await wait_for(lambda: vehicle.px4_events.decoder is not None, 30.0, "events metadata")
        old_decoder = vehicle.px4_events.decoder
        await _fly_offboard(api)
        changed = await api.client.put(
            f"/api/v1/vehicles/{sitl.sysid}/params/MIS_TAKEOFF_ALT", json={"value": 7.0},
            headers=api.lease_headers,
        )
        assert changed.status_code == 200, changed.text
        events = vehicle.subscribe_events(1024)

        restarted = time.monotonic()
        px4_process.stop()
        px4_process.start(clean=False)  # parameters kept, as on a real vehicle's reboot
        reboot = await _next_event(events, "reboot", 60.0)
        detect_s = time.monotonic() - restarted
        assert "boot time went back" in reboot["reason"]
        assert not vehicle.streamer_active

        async def settled() -> dict[str, Any] | None:
            state = await rest_state(api.client, sitl.sysid)
            return state if state["connected"] and not state["stale"] else None

        state = await eventually(settled, 30.0, "fresh state after the reboot")
        recover_s = time.monotonic() - restarted
        assert state["armed"] is False
        assert state["mode"] != "OFFBOARD"
        assert state["stream"]["active"] is False
        assert sum(1 for t, c in tap.commands
                   if t >= restarted and c == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL) >= 5
        await wait_for(lambda: any(t >= restarted and n == "MIS_TAKEOFF_ALT"
                                   for t, n in tap.param_reads), 20.0, "parameters read again")
        await wait_for(lambda: vehicle.params.cache.get("MIS_TAKEOFF_ALT") is not None, 20.0,
                       "the value read again")
        # the cache holds what the restarted PX4 says (the SITL kit came back with its
        # default, 2.5, not the 7.0 set before: recorded in docs/RELIABILITY.md)
        reread = vehicle.params.cache["MIS_TAKEOFF_ALT"].value
        direct = await api.client.get(f"/api/v1/vehicles/{sitl.sysid}/params/MIS_TAKEOFF_ALT")
        assert direct.json()["value"] == reread
        await wait_for(lambda: vehicle.px4_events.decoder not in (None, old_decoder), 30.0,
                       "events metadata loaded again")
    print(f"\nPX4 restart: reboot noticed {detect_s:.2f} s after the restart began, state "
          f"fresh after {recover_s:.2f} s, MIS_TAKEOFF_ALT read again: {reread} (set 7.0)")
