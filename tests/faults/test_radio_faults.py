"""Faults as a telemetry radio has them, while the simulated PX4 (real time) hovers in
OFFBOARD on SkyHelm's stream behind the fault proxy: HEARTBEATs alone lost for 3.6 s,
burst loss (Gilbert–Elliott, mean burst 5 frames) at 10, 20 and 40 %, loss one way only,
20 % duplication and 20 % reordering. None of them is a lost vehicle: the stream goes on
and the vehicle stays in OFFBOARD; the link's loss figure follows the proxy's drops. A
real cut both ways is still shown within 1.5 s. Figures are printed (-s) and listed in
docs/RELIABILITY.md."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass

import pytest
import pytest_asyncio
from pymavlink.dialects.v20 import development as mavlink

from bench.hostile_input import kernel_drops
from server.link import Vehicle
from sim.vehicle import SimVehicle
from tests.api.conftest import OBSERVER, Api, api_for
from tests.faults.conftest import message_id
from tests.faults.linkloss_rig import Rig, WsLog, proxied_sim, ws_logging
from tests.serving import uvicorn_serving
from tests.waiting import wait_for
from tools.faultproxy import MAVLINK_MSG_ID_HEARTBEAT, NO_FAULTS, DirectionChoice, Faults

pytestmark = pytest.mark.asyncio(loop_scope="module")

HOVER = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -3.0}
HEARTBEAT_DROP_S = 3.6
HEARTBEAT_DROP_MAX_S = 8.0
FAULT_S = 5.0
CUT_SHOWN_WITHIN_S = 1.5
STREAM_RATE_HZ = 50.0
# PX4's COM_OF_LOSS_T default: a setpoint older than this is an offboard loss
OF_LOSS_S = 1.0
SET_POSITION_TARGET_LOCAL_NED = mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED


@dataclass
class Flight:
    rig: Rig
    api: Api
    log: WsLog
    # setpoints as they reached the proxy from the server, and as it handed them on
    setpoints_from_server: int = 0
    setpoints_to_vehicle: int = 0

    def count_sent(self, direction: str, frame: bytes) -> None:
        if direction == "to_vehicle" and message_id(frame) == SET_POSITION_TARGET_LOCAL_NED:
            self.setpoints_from_server += 1

    def count_received(self, direction: str, frame: bytes) -> None:
        if direction == "to_vehicle" and message_id(frame) == SET_POSITION_TARGET_LOCAL_NED:
            self.setpoints_to_vehicle += 1

    @property
    def server_vehicle(self) -> Vehicle:
        return self.api.vehicle()

    @property
    def sim(self) -> SimVehicle:
        return self.rig.vehicle

    async def hovering(self) -> None:
        """Connected and in OFFBOARD on the stream (a setpoint brings it back if not)."""
        await wait_for(lambda: self.server_vehicle.connected, 10.0, "the vehicle connected")
        if self.sim.mode_name != "OFFBOARD" or not self.server_vehicle.streamer_active:
            answer = await self.api.control("setpoint", HOVER)
            assert answer.status_code == 200, answer.text
        await wait_for(lambda: self.sim.mode_name == "OFFBOARD", 10.0, "OFFBOARD")

    def lost_events(self) -> int:
        return sum(1 for e in self.log.events("connection") if e["connected"] is False)

    async def holds_flying(self, duration_s: float, what: str) -> None:
        """For duration_s: never lost, streaming, the vehicle in OFFBOARD and fed."""
        loop = asyncio.get_running_loop()
        end = loop.time() + duration_s
        lost_before = self.lost_events()
        while loop.time() < end:
            assert self.server_vehicle.connected, f"{what}: the vehicle was judged lost"
            assert self.server_vehicle.streamer_active, f"{what}: the stream stopped"
            assert self.sim.mode_name == "OFFBOARD", f"{what}: the vehicle left OFFBOARD"
            offboard = self.sim.commander.offboard
            assert self.sim.now_s - offboard.received_s < OF_LOSS_S, f"{what}: setpoints stopped"
            await asyncio.sleep(0.01)
        assert self.lost_events() == lost_before


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def flight() -> AsyncIterator[Flight]:
    async with proxied_sim(seed=22) as rig, api_for(None, connect=[rig.url], lease_ttl_s=600.0,
                                                   rate_hz=STREAM_RATE_HZ) as api:
        await wait_for(lambda: api.app.state.api.registry.get(1) is not None, 10.0, "discovery")
        await api.wait_ready()
        async with uvicorn_serving(api.app) as host:
            url = f"ws://{host}/api/v1/ws/telemetry?token={OBSERVER}&vehicle=1&rate_hz=10"
            async with ws_logging(url) as log:
                await api.take_control()
                assert (await api.control("arm")).status_code == 200
                start = await api.control("offboard/start", {"setpoint": HOVER})
                assert start.status_code == 200, start.text
                await api.wait_state(lambda s: s["position_ned"]["down_m"] < -2.5, 20.0,
                                     "climb to 2.5 m")
                flight = Flight(rig, api, log)
                rig.proxy.add_tap(flight.count_sent, arriving=True)
                rig.proxy.add_tap(flight.count_received)
                yield flight


async def test_heartbeats_alone_lost_for_3_6_s_warn_but_never_lose_the_vehicle(
    flight: Flight,
) -> None:
    await flight.hovering()
    warnings_before = len(flight.log.events("link_quality"))
    sim_start_s = flight.sim.now_s
    flight.rig.proxy.drop_messages({MAVLINK_MSG_ID_HEARTBEAT}, HEARTBEAT_DROP_S, "to_server")
    await flight.holds_flying(HEARTBEAT_DROP_S, "HEARTBEATs dropped")
    # a loop that stood still forgives the link its stall (liveness.forgive): on a starved
    # machine the HEARTBEAT's age reaches the warning later, so the drop goes on until it does
    dropped_s = HEARTBEAT_DROP_S
    while dropped_s < HEARTBEAT_DROP_MAX_S and not any(
        "heartbeat" in e["causes"] for e in flight.log.events("link_quality")[warnings_before:]
    ):
        flight.rig.proxy.drop_messages({MAVLINK_MSG_ID_HEARTBEAT}, 1.0, "to_server")
        await flight.holds_flying(0.5, "HEARTBEATs dropped")
        dropped_s += 0.5
    # the sim sends one HEARTBEAT a second of its own time, which a busy machine slows
    sim_drop_s = flight.sim.now_s - sim_start_s
    await flight.holds_flying(1.5, "HEARTBEATs back")
    quality = flight.log.events("link_quality")[warnings_before:]
    # the warning before any verdict: the HEARTBEAT late while other frames arrive...
    assert any("heartbeat" in e["causes"] for e in quality), quality
    # ...and over when they come back
    await wait_for(lambda: "heartbeat" not in flight.log.events("link_quality")[-1]["causes"],
                   5.0, "the heartbeat warning over")
    assert flight.rig.proxy.counters()["to_server"].filtered >= min(3, int(sim_drop_s)), sim_drop_s


RADIO_FAULTS: list[tuple[str, Faults, DirectionChoice]] = [
    ("burst 10%", Faults(loss_pct=10.0, burst_frames=5.0), "both"),
    ("burst 20%", Faults(loss_pct=20.0, burst_frames=5.0), "both"),
    ("burst 40%", Faults(loss_pct=40.0, burst_frames=5.0), "both"),
    ("20% towards the vehicle only", Faults(loss_pct=20.0), "to_vehicle"),
    ("20% towards the server only", Faults(loss_pct=20.0), "to_server"),
    ("duplication 20%", Faults(duplicate_pct=20.0), "both"),
    ("reordering 20%", Faults(reorder_pct=20.0), "both"),
]


@pytest.mark.parametrize(("name", "faults", "direction"), RADIO_FAULTS,
                         ids=[name for name, _, _ in RADIO_FAULTS])
async def test_radio_faults_keep_the_vehicle_flying_and_the_loss_figure_true(
    flight: Flight, name: str, faults: Faults, direction: DirectionChoice,
) -> None:
    await flight.hovering()
    proxy = flight.rig.proxy
    (link,) = flight.api.app.state.api.registry.links
    lost_before = link.stats().lost_frames
    # the kernel drops too, for a full receive buffer, when this loaded process (the sim,
    # the proxy and the server in one) stalls and then bursts: a loss as real as the proxy's
    drop_ports = (proxy.vehicle_facing_address[1], link.local_address[1])
    kernel_before = _kernel_drops(drop_ports)
    to_server = proxy.counters()["to_server"]
    dropped_before, passed_before = to_server.dropped, to_server.out
    sent_before = flight.setpoints_from_server
    received_before = flight.setpoints_to_vehicle
    proxy.configure(faults, direction)
    try:
        await flight.holds_flying(FAULT_S, name)
    finally:
        proxy.configure(NO_FAULTS)
    kernel = _kernel_drops(drop_ports) - kernel_before
    dropped = to_server.dropped - dropped_before + kernel
    # a gap is counted when the frame after it arrives: let the drops at the very end of the
    # fault be followed (a loaded machine may still hold those frames back)
    frames_in = link.stats().frames_in
    await wait_for(lambda: link.stats().frames_in >= frames_in + 50, 5.0, "frames after")
    counted = link.stats().lost_frames - lost_before
    quality = flight.server_vehicle.snapshot().link_quality
    assert quality is not None
    sent = flight.setpoints_from_server - sent_before
    received = flight.setpoints_to_vehicle - received_before
    drop_pct = 100.0 * dropped / max(1, dropped + to_server.out - passed_before)
    print(f"\n{name}: vehicle -> server dropped {dropped} ({drop_pct:.1f}%, {kernel} of them "
          f"by the kernel), link counted "
          f"{counted} lost, loss_in_pct {quality.loss_in_pct}, loss_out_pct "
          f"{quality.loss_out_pct}, degraded {quality.causes}; setpoints sent {sent}, "
          f"received by the vehicle {received} ({100 * received / max(1, sent):.1f}%)")
    # a duplicate is no loss and a late frame is taken back: the count follows the drops
    assert abs(counted - dropped) <= max(5, 0.05 * dropped), (counted, dropped)
    assert received > 0
    if direction == "to_vehicle" and faults.loss_pct:
        # what the vehicle reports missing of ours (LINK_NODE_STATUS, 1 Hz, last 5 s)
        assert quality.loss_out_pct is not None
        assert 10.0 <= quality.loss_out_pct <= 30.0


async def test_a_real_cut_both_ways_is_shown_within_1_5_s(flight: Flight) -> None:
    await flight.hovering()
    vehicle = flight.server_vehicle
    lags_s: list[float] = []
    probe = asyncio.create_task(_loop_lag(lags_s))
    cut = time.monotonic()
    flight.rig.proxy.partition(3.0)
    await wait_for(lambda: not vehicle.connected, 5.0, "the loss shown")
    shown_s = time.monotonic() - cut
    probe.cancel()
    # a loaded machine may not run this process for a while: the server (in this process)
    # could not show anything then, so the longest such stall is not held against it
    stalled_s = max(lags_s, default=0.0)
    print(f"\ncut both ways: lost shown after {shown_s:.2f} s (the process stood still up "
          f"to {stalled_s:.2f} s meanwhile)")
    assert shown_s - stalled_s < CUT_SHOWN_WITHIN_S
    await wait_for(lambda: vehicle.connected, 10.0, "the vehicle back")
    await flight.hovering()


async def _loop_lag(lags_s: list[float]) -> None:
    """How late this process's event loop wakes from a 10 ms sleep, again and again."""
    loop = asyncio.get_running_loop()
    while True:
        due = loop.time() + 0.01
        await asyncio.sleep(0.01)
        lags_s.append(loop.time() - due)


def _kernel_drops(ports: tuple[int, ...]) -> int:
    return sum(kernel_drops(port) or 0 for port in ports)
