"""The UDP endpoint: robustness against bad datagrams, answering whoever talks, ports."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator
from typing import Any, cast

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.mavlink.endpoint import MavlinkCodec, UdpLink, open_link
from sim.process.clock import ManualClock
from sim.process.run_loop import MIN_WAKE_PERIOD_S
from sim.process.runner import SimCluster
from sim.vehicle import PHYSICS_DT_S, READY_TIME_S
from tests.sim.conftest import PointMassAirframe, point_mass_defaults


class UdpPeer(asyncio.DatagramProtocol):
    """A GCS-like UDP socket on an ephemeral port, decoding what it receives."""

    def __init__(self) -> None:
        self.port = 0
        self.received: list[Any] = []
        self._transport: asyncio.DatagramTransport | None = None
        self._arrived = asyncio.Event()
        self._mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.DatagramTransport, transport)
        self.port = transport.get_extra_info("sockname")[1]

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.received.extend(mavlink.MAVLink(None).parse_buffer(data) or [])
        self._arrived.set()

    def send_bytes(self, data: bytes, port: int) -> None:
        assert self._transport is not None
        self._transport.sendto(data, ("127.0.0.1", port))

    def encode(self, msg: Any) -> bytes:
        data: bytes = msg.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        return data

    def send(self, msg: Any, port: int) -> None:
        self.send_bytes(self.encode(msg), port)

    async def wait_for(self, type_name: str, timeout_s: float = 5.0,
                       sysid: int | None = None) -> Any:
        """The first message of that type (and sender) received, waiting for it to come."""
        async with asyncio.timeout(timeout_s):
            while True:
                for m in self.received:
                    if m.get_type() == type_name and (sysid is None or m.get_srcSystem() == sysid):
                        return m
                self._arrived.clear()
                await self._arrived.wait()

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()


async def open_peer() -> UdpPeer:
    _, peer = await asyncio.get_running_loop().create_datagram_endpoint(
        UdpPeer, local_addr=("127.0.0.1", 0))
    return peer


@pytest.fixture
async def peer() -> AsyncIterator[UdpPeer]:
    p = await open_peer()
    yield p
    p.close()


def cluster(**kwargs: Any) -> SimCluster:
    return SimCluster(airframe_factory=PointMassAirframe, defaults_factory=point_mass_defaults,
                      **kwargs)


def heartbeat() -> Any:
    return mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)


async def test_answers_whoever_talks_on_either_socket(peer: UdpPeer) -> None:
    async with cluster(speed=5.0) as sim:
        inst = sim.instances[0]
        assert inst.api_local_port > 0
        assert inst.gcs_local_port > 0
        peer.send(heartbeat(), inst.api_local_port)
        hb = await peer.wait_for("HEARTBEAT")
        assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
        other = await open_peer()
        try:
            other.send(heartbeat(), inst.gcs_local_port)
            await other.wait_for("HEARTBEAT")
        finally:
            other.close()


async def test_sends_to_configured_remote_port_before_anyone_talks(peer: UdpPeer) -> None:
    async with cluster(speed=5.0, api_port=peer.port):
        await peer.wait_for("HEARTBEAT")
        await peer.wait_for("ATTITUDE_QUATERNION")  # onboard stream set


async def test_gcs_port_is_shared_by_all_instances(peer: UdpPeer) -> None:
    async with cluster(count=3, speed=5.0, gcs_port=peer.port) as sim:
        assert [i.sysid for i in sim.instances] == [1, 2, 3]
        assert len({i.api_local_port for i in sim.instances}) == 3
        for sysid in (1, 2, 3):
            await peer.wait_for("HEARTBEAT", sysid=sysid)


async def test_garbage_truncated_and_bad_crc_datagrams_are_counted_and_dropped(
    peer: UdpPeer,
) -> None:
    async with cluster(speed=5.0) as sim:
        await sim.wait_ready(timeout_s=5.0)
        inst = sim.instances[0]
        port = inst.api_local_port
        arm = mavlink.MAVLink_command_long_message(
            1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        frame = peer.encode(arm)
        bad_crc = bytearray(peer.encode(arm))
        bad_crc[-1] ^= 0xFF
        peer.send_bytes(b"this is not mavlink", port)
        peer.send_bytes(frame[: len(frame) // 2], port)
        peer.send_bytes(bytes(bad_crc), port)
        peer.send(arm, port)
        # datagrams from one socket to another on loopback arrive in order: once the ack
        # of the last one is back, the three before it have been dealt with
        ack = await peer.wait_for("COMMAND_ACK")
        assert ack.result == mavlink.MAV_RESULT_ACCEPTED
        assert inst.rx_dropped == 3
        assert inst.api_link.counters.rx_messages == 1


def test_codec_decodes_two_frames_in_one_datagram() -> None:
    sender = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    data = heartbeat().pack(sender) + heartbeat().pack(sender)
    messages, bad, unverified = MavlinkCodec(1, 1).decode(data)
    assert [m.get_type() for m in messages] == ["HEARTBEAT", "HEARTBEAT"]
    assert (bad, unverified) == (0, 0)


async def test_speed_runs_sim_time_faster_than_wall_time() -> None:
    clock = ManualClock()
    async with cluster(speed=5.0, clock=clock) as sim:
        await clock.advance(1.0)
        # sim time is 5 s less what is due after the last wake-up (one wake period)
        now_s = sim.instances[0].vehicle.now_s
        assert 5.0 - 5.0 * MIN_WAKE_PERIOD_S - PHYSICS_DT_S <= now_s <= 5.0 + 1e-9


async def test_a_fast_forward_sends_each_stream_at_most_its_cap_per_wall_second(
    peer: UdpPeer,
) -> None:
    """The cluster's pace reaches the vehicles' streams: at 8x, ATTITUDE (100 Hz in PX4)
    goes out about 100 times per wall second, not 800; at real time, 100 again."""
    clock = ManualClock()
    async with cluster(speed=1.0, clock=clock, api_port=peer.port) as sim:
        vehicle, link = sim.instances[0].vehicle, sim.instances[0].api_link
        sent: list[str] = []
        send = link.send

        def recording_send(msg: Any) -> None:
            sent.append(msg.get_type())
            send(msg)

        link.send = recording_send  # type: ignore[method-assign]
        await clock.advance(2.0)  # booted and streaming

        async def attitudes_in_one_wall_second() -> int:
            before = sent.count("ATTITUDE")
            for _ in range(10):
                await clock.advance(0.1)
            return sent.count("ATTITUDE") - before

        with sim.fast_forwarded(8.0):
            assert vehicle.wall_speed() == 8.0
            fast = await attitudes_in_one_wall_second()
        assert vehicle.wall_speed() == 1.0
        real_time = await attitudes_in_one_wall_second()
    assert 90 <= fast <= 110
    assert 90 <= real_time <= 110


async def test_wait_ready_returns_after_boot_at_the_speed_asked_for() -> None:
    async with cluster(speed=5.0) as sim:
        start_wall = time.monotonic()
        await sim.wait_ready(timeout_s=5.0)
        elapsed_wall = time.monotonic() - start_wall
        vehicle = sim.instances[0].vehicle
        assert vehicle.ready
        assert vehicle.now_s >= READY_TIME_S
        # real time: sim time runs five times as fast, give or take the loop's start-up
        assert 3.5 < vehicle.now_s / elapsed_wall <= 5.2


class _UnpackableMessage:
    """A foreign message type whose own pack fails, as a malformed one would."""

    def get_type(self) -> str:
        return "UNPACKABLE"

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        raise ValueError("field out of range")


class _RecordingTransport:
    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def sendto(self, data: bytes, addr: Any = None) -> None:
        self.sent.append(data)

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        return ("127.0.0.1", 0) if name == "sockname" else default


def test_frame_that_cannot_be_packed_is_counted_and_skipped() -> None:
    link = UdpLink("api", 1, 1, lambda link, msg: None, remote=("127.0.0.1", 9))
    transport = _RecordingTransport()
    link.connection_made(transport)  # type: ignore[arg-type]
    link.send(_UnpackableMessage())
    link.send(mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3))
    assert link.counters.tx_unpackable == 1
    assert link.counters.tx_messages == 1
    (frame,) = transport.sent
    (decoded,) = mavlink.MAVLink(None).parse_buffer(frame) or []
    assert decoded.get_type() == "HEARTBEAT"
    assert decoded.get_seq() == 0


# A loop turn as long as a starved vehicle's step batch; datagrams that came meanwhile.
SLOW_TURN_S = 0.02
WAITING_DATAGRAMS = 300


def _hold_the_loop(seconds: float) -> None:
    time.sleep(seconds)  # the vehicle's steps: nothing else runs on the loop meanwhile


async def test_a_slowly_turning_loop_reads_every_waiting_datagram_at_once(
        peer: UdpPeer) -> None:
    """asyncio alone hands a datagram endpoint one datagram per turn of the loop: with a
    turn of 20-30 ms, 300 waiting setpoints took 9 s, a command behind them as late."""
    taken: list[Any] = []
    all_taken = asyncio.Event()

    def take(_link: UdpLink, msg: Any) -> None:
        taken.append(msg)
        if len(taken) == WAITING_DATAGRAMS:
            all_taken.set()

    link = await open_link("api", 1, 1, take, "127.0.0.1", 0, None)
    turning = True

    async def slow_turns() -> None:
        while turning:
            _hold_the_loop(SLOW_TURN_S)
            await asyncio.sleep(0)

    try:
        for _ in range(WAITING_DATAGRAMS):
            peer.send(heartbeat(), link.local_port)
        turns = asyncio.create_task(slow_turns())
        started = time.monotonic()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(all_taken.wait(), 10.0)
        took_s = time.monotonic() - started
        turning = False
        await turns
    finally:
        link.close()
    assert len(taken) == WAITING_DATAGRAMS
    assert took_s < 10 * SLOW_TURN_S, f"{WAITING_DATAGRAMS} datagrams took {took_s:.2f} s"
