"""20% loss both ways between SkyHelm and the simulated vehicle (a FaultProxy in between).

Every command either resolves with the vehicle's real answer (after retries) or reports a
timeout truthfully (504, result TIMEOUT), never a wrong answer: whatever SkyHelm says was
ACCEPTED is checked against the vehicle's own state. Parameters read, write and list
complete. The setpoint stream's rate is measured where it matters, at the vehicle's receiver,
not from what the server says it sent. Figures are printed (run with -s) and listed in
docs/RELIABILITY.md."""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

import httpx
import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.lib import modes
from sim.process.runner import SimCluster
from tests.api.conftest import Api, sim_cluster
from tests.faults.conftest import api_through, message_id, vehicle_behind_proxy
from tests.waiting import wait_for
from tools.faultproxy import FaultProxy, Faults

LOSS_PCT = 20.0
STREAM_RATE_HZ = 100.0
# setpoints measured at the vehicle: 20% loss of n is binomial; at n = 600 one standard
# deviation of the received share is 1.6 points, and the bounds below are 4 of them
MEASURED_SETPOINTS = 600
RECEIVED_SHARE_BOUNDS = (0.735, 0.865)
# an operator retrying a 504 up to this many times; each call already tries 4 times
TRIES = 4
PARAM_TO_SET = "MIS_TAKEOFF_ALT"


@dataclass
class Scenario:
    api: Api
    proxy: FaultProxy
    sim: SimCluster
    timeouts: dict[str, int] = field(default_factory=dict)  # operation -> 504s seen
    # setpoints counted as the proxy sent them on, and as the vehicle's receiver took them
    setpoints_out: int = 0
    setpoint_arrivals: list[float] = field(default_factory=list)

    @property
    def commander(self) -> Any:
        return self.sim.instances[0].vehicle.commander

    async def until_answered(
        self, what: str, call: Callable[[], Any], truth: Callable[[], bool]
    ) -> httpx.Response:
        """Call until an answer that is not a timeout; every 504 must say TIMEOUT, and an
        ACCEPTED must be true of the vehicle."""
        for _ in range(TRIES):
            response: httpx.Response = await call()
            if response.status_code != 504:
                break
            body = response.json()
            assert body.get("result", "TIMEOUT") == "TIMEOUT", body
            if "result" not in body:  # parameters answer 504 with a reason
                assert "no answer" in body["detail"]["reason"] or "no echo" in str(body), body
            self.timeouts[what] = self.timeouts.get(what, 0) + 1
        assert response.status_code == 200, f"{what}: {response.status_code} {response.text}"
        if "result" in response.json():
            assert response.json()["result"] == "ACCEPTED", response.text
        # what SkyHelm reported is what the vehicle did
        assert truth(), f"{what} answered {response.text} but the vehicle disagrees"
        return response


@pytest.fixture
async def scenario() -> AsyncIterator[Scenario]:
    async with (
        # real time: PX4's offboard-loss timeout (COM_OF_LOSS_T) is then real seconds, so a
        # loaded machine's scheduling stalls cannot pass for a lost stream
        sim_cluster("quad", speed=1.0) as sim,
        vehicle_behind_proxy(sim, seed=20) as proxy,
    ):
        proxy.configure(Faults(loss_pct=LOSS_PCT))
        async with api_through(proxy, sim, rate_hz=STREAM_RATE_HZ, lease_ttl_s=120.0) as api:
            run = Scenario(api, proxy, sim)

            def count_setpoints(direction: str, frame: bytes) -> None:
                if (direction == "to_vehicle" and message_id(frame)
                        == mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED):
                    run.setpoints_out += 1

            proxy.add_tap(count_setpoints)
            receiver = sim.instances[0].vehicle.receiver
            handle = receiver.handle

            def noting(link: Any, msg: Any) -> None:
                if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
                    run.setpoint_arrivals.append(asyncio.get_running_loop().time())
                handle(link, msg)

            receiver.handle = noting  # type: ignore[method-assign]
            await api.wait_state(
                lambda s: s["global"] is not None and s["home"] is not None, 30.0,
                "position and home through the lossy link", renew=False,
            )
            await api.take_control()
            yield run


async def test_commands_params_and_stream_through_20pct_loss(scenario: Scenario) -> None:
    run, api = scenario, scenario.api
    commander = run.commander
    vehicle_params = run.sim.instances[0].vehicle.params

    # -- parameters: one read, one write, the whole list ---------------------------------
    read = await run.until_answered(
        "param read", lambda: api.client.get(f"/api/v1/vehicles/1/params/{PARAM_TO_SET}"),
        lambda: True,
    )
    assert read.json()["value"] == pytest.approx(vehicle_params.get(PARAM_TO_SET))
    await run.until_answered(
        "param write",
        lambda: api.client.put(f"/api/v1/vehicles/1/params/{PARAM_TO_SET}",
                               json={"value": 4.0}, headers=api.lease_headers),
        lambda: vehicle_params.get(PARAM_TO_SET) == pytest.approx(4.0),
    )
    listed = await run.until_answered(
        "param list", lambda: api.client.get("/api/v1/vehicles/1/params"), lambda: True
    )
    params = listed.json()["params"]
    assert set(params) == set(vehicle_params)
    assert all(params[name] == pytest.approx(vehicle_params.value(name)) for name in params)
    assert "param list" not in run.timeouts  # the list completes in one call

    # -- commands, each checked against the vehicle --------------------------------------
    await run.until_answered("arm", lambda: api.control("arm"), lambda: commander.armed)
    await run.until_answered(
        "takeoff", lambda: api.control("takeoff", {"altitude_m": 5.0}),
        lambda: commander.armed and commander.nav_mode in (modes.AUTO_TAKEOFF, modes.AUTO_LOITER),
    )
    await api.wait_state(lambda s: s["position_ned"]["down_m"] < -4.0, 30.0, "climb to 4 m")
    start_body = {"setpoint": {"type": "position_ned", "north_m": 0.0, "east_m": 0.0,
                               "down_m": -5.0}}
    await run.until_answered(
        "offboard start", lambda: api.control("offboard/start", start_body),
        lambda: commander.nav_mode == modes.OFFBOARD,
    )

    # -- the stream at the vehicle, in OFFBOARD ------------------------------------------
    (link,) = api.app.state.api.registry.links
    link_before = link.stats()
    dropped_before = run.proxy.counters()["to_server"].dropped
    streamer_sent = api.vehicle().stream_stats().sent
    out_before, first = run.setpoints_out, len(run.setpoint_arrivals)
    loop = asyncio.get_running_loop()
    started = loop.time()
    await holds_for_setpoints(run, commander, first)
    elapsed_s = loop.time() - started
    sent = api.vehicle().stream_stats().sent - streamer_sent
    arrivals = run.setpoint_arrivals[first:]
    received = len(arrivals)
    share = received / sent
    gaps = [b - a for a, b in itertools.pairwise(arrivals)]
    largest_gap_s = max(gaps)
    print(
        f"\n20% loss both ways, stream {STREAM_RATE_HZ:g} Hz: server sent {sent}, proxy passed "
        f"{run.setpoints_out - out_before}, vehicle received {received} "
        f"({100 * share:.1f}%, {received / elapsed_s:.1f} Hz), largest gap at the vehicle "
        f"{1000 * largest_gap_s:.0f} ms; commands/params that timed out (504) and were "
        f"retried: {run.timeouts or 'none'}; proxy {run.proxy.stats()}"
    )
    # the link's count of frames lost (gaps in the vehicle's sequence numbers) is the
    # proxy's count of datagrams dropped towards it; a gap is seen at the next frame, so
    # the drops just before each end of the window may fall on either side
    link_after = link.stats()
    dropped = run.proxy.counters()["to_server"].dropped - dropped_before
    lost = link_after.lost_frames - link_before.lost_frames
    print(f"vehicle -> server in the same window: proxy dropped {dropped}, link counted "
          f"{lost} lost frames, {link_after.bad_frames} bad frames")
    assert abs(lost - dropped) <= 10
    assert link_after.bad_frames == 0
    low, high = RECEIVED_SHARE_BOUNDS
    assert low <= share <= high, share
    # what reached the vehicle is what the proxy let through (nothing lost on loopback)
    assert abs(received - (run.setpoints_out - out_before)) <= 2
    # PX4's offboard-loss failsafe never fired: no gap reached COM_OF_LOSS_T (sim seconds)
    of_loss_t_wall_s = vehicle_params.get("COM_OF_LOSS_T") / run.sim.speed
    assert largest_gap_s < of_loss_t_wall_s
    assert not commander.failsafe

    # -- and down (the landing itself is not this test's) --------------------------------
    await run.until_answered("hold", lambda: api.control("hold"),
                             lambda: commander.nav_mode == modes.AUTO_LOITER)
    await run.until_answered("land", lambda: api.control("land"),
                             lambda: commander.nav_mode == modes.AUTO_LAND)


async def holds_for_setpoints(run: Scenario, commander: Any, first: int) -> None:
    """Until MEASURED_SETPOINTS have arrived, the vehicle staying in OFFBOARD throughout."""
    budget_s = 20 * MEASURED_SETPOINTS / STREAM_RATE_HZ
    await wait_for(lambda: _stayed_offboard(run, commander, first), budget_s,
                   "enough setpoints at the vehicle", poll_s=0.02)


def _stayed_offboard(run: Scenario, commander: Any, first: int) -> bool:
    assert commander.nav_mode == modes.OFFBOARD, f"the vehicle left OFFBOARD: {commander.nav_mode}"
    return len(run.setpoint_arrivals) - first >= MEASURED_SETPOINTS
