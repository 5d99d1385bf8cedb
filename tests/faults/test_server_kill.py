"""`skyhelm serve --connect ...` killed with SIGKILL while the vehicle flies OFFBOARD (the
simulated PX4 behind the fault proxy): the vehicle applies its offboard-loss failsafe, the
.tlog recorded so far reads cleanly, and a restarted server finds the vehicle again, shows
its real mode and streams nothing until an operator takes control."""

from __future__ import annotations

import signal
import time
from pathlib import Path
from typing import Any

import httpx

from server.link.codec.tlog import iter_tlog
from tests.faults.linkloss_rig import Rig, proxied_sim, read_tlog
from tests.serve_process import Served, skyhelm_serve
from tests.waiting import eventually, holds_for, wait_for

CLIMB_TO = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -5.0}


def _client(served: Served) -> httpx.AsyncClient:
    return httpx.AsyncClient(
        base_url=served.api, headers={"Authorization": f"Bearer {served.pilot_token}"},
        timeout=30.0,
    )


async def _state(client: httpx.AsyncClient) -> dict[str, Any] | None:
    response = await client.get("/vehicles/1")
    if response.status_code != 200:
        return None
    result: dict[str, Any] = response.json()
    return result


async def _fly_offboard(client: httpx.AsyncClient) -> None:
    async def ready() -> bool:
        state = await _state(client)
        return state is not None and state["home"] is not None and state["global"] is not None

    await eventually(ready, 20.0, "the vehicle ready on the server")
    taken = await client.post("/vehicles/1/control", json={})
    assert taken.status_code == 200, taken.text
    lease = {"X-Lease-Id": taken.json()["lease_id"]}
    assert (await client.post("/vehicles/1/arm", json={}, headers=lease)).status_code == 200
    start = await client.post("/vehicles/1/offboard/start", json={"setpoint": CLIMB_TO},
                              headers=lease)
    assert start.status_code == 200, start.text

    async def climbed() -> bool:
        await client.put("/vehicles/1/control", headers=lease)  # renew
        state = await _state(client)
        return state is not None and state["position_ned"]["down_m"] < -4.0

    await eventually(climbed, 20.0, "climb to 4 m")


async def test_server_sigkill_in_offboard_failsafe_tlog_and_rediscovery(tmp_path: Path) -> None:
    async with proxied_sim() as rig:
        first_logs = tmp_path / "first"
        first_logs.mkdir()
        with skyhelm_serve(first_logs, "--connect", rig.url, "--no-scene") as served:
            async with _client(served) as client:
                await _fly_offboard(client)
            assert rig.vehicle.mode_name == "OFFBOARD"
            assert served.process is not None
            killed_at = time.monotonic()
            served.process.send_signal(signal.SIGKILL)
            served.process.wait(timeout=10)
        await _vehicle_fails_safe(rig, killed_at)

        path, messages, records = read_tlog(first_logs)
        assert messages > 100
        assert messages == records  # pymavlink reads every whole record iter_tlog finds
        lost_tail_s = killed_at - _last_record_age(path)

        second_logs = tmp_path / "second"
        second_logs.mkdir()
        with skyhelm_serve(second_logs, "--connect", rig.url, "--no-scene") as served:
            restarted_at = time.monotonic()  # serving: from here it looks for the vehicle
            async with _client(served) as client:

                async def rediscovered() -> dict[str, Any] | None:
                    state = await _state(client)
                    # the intended mode comes with CURRENT_MODE, which may trail the
                    # first HEARTBEAT a little on a loaded machine
                    fresh = state is not None and not state["stale"]
                    return state if fresh and state["user_mode"] is not None else None

                state = await eventually(rediscovered, 20.0, "the vehicle found again")
                found_s = time.monotonic() - restarted_at
                assert state["mode"] == rig.vehicle.mode_name == "POSCTL"
                assert state["user_mode"] == "OFFBOARD"
                assert state["stream"]["active"] is False
                assert state["lease"]["holder"] is None
                received_s = rig.vehicle.commander.offboard.received_s
                await holds_for(
                    lambda: rig.vehicle.commander.offboard.received_s == received_s
                    and rig.vehicle.mode_name != "OFFBOARD",
                    1.5, "no setpoint until an operator takes control",
                )
        print(f"\nserver SIGKILL in OFFBOARD (sim): tlog {messages} messages, the last "
              f"{lost_tail_s:.2f} s before the kill unwritten; restarted server found the "
              f"vehicle in {state['mode']} after {found_s:.2f} s")


async def _vehicle_fails_safe(rig: Rig, killed_at: float) -> None:
    sim = rig.vehicle
    await wait_for(lambda: sim.mode_name != "OFFBOARD", 10.0, "the vehicle's failsafe")
    assert sim.mode_name == "POSCTL"  # COM_OBL_RC_ACT 0: Position
    assert sim.commander.user_mode.name == "OFFBOARD"
    assert sim.now_s - sim.commander.offboard.received_s >= sim.params.get("COM_OF_LOSS_T")
    assert time.monotonic() - killed_at < 5.0


def _last_record_age(path: Path) -> float:
    """Wall time of the last record, as time.monotonic() would have read it then."""
    last_unix_s = max(t for t, _ in iter_tlog(path))
    return time.monotonic() - (time.time() - last_unix_s)
