"""The UDP endpoint: robustness against bad datagrams, answering whoever talks, ports."""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.endpoint import MavlinkCodec, UdpLink
from sim.runner import SimCluster
from tests.sim.conftest import PointMassAirframe, point_mass_defaults


class UdpPeer:
    """A GCS-like UDP socket on an ephemeral port, decoding what it receives."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.port: int = self.sock.getsockname()[1]
        self._mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.received: list[Any] = []

    def send_bytes(self, data: bytes, port: int) -> None:
        self.sock.sendto(data, ("127.0.0.1", port))

    def encode(self, msg: Any) -> bytes:
        data: bytes = msg.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        return data

    def send(self, msg: Any, port: int) -> None:
        self.send_bytes(self.encode(msg), port)

    def drain(self) -> None:
        parser = mavlink.MAVLink(None)
        while True:
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                return
            self.received.extend(parser.parse_buffer(data) or [])

    async def wait_for(self, type_name: str, timeout_s: float = 5.0,
                       sysid: int | None = None) -> Any:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.drain()
            for m in self.received:
                if m.get_type() == type_name and (sysid is None or m.get_srcSystem() == sysid):
                    return m
            await asyncio.sleep(0.01)
        raise AssertionError(f"no {type_name} within {timeout_s} s")

    def close(self) -> None:
        self.sock.close()


async def poll_until(condition: Callable[[], bool], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"condition not met within {timeout_s} s")
        await asyncio.sleep(0.01)


@pytest.fixture
async def peer() -> AsyncIterator[UdpPeer]:
    p = UdpPeer()
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
        other = UdpPeer()
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
        await poll_until(lambda: inst.api_link.counters.rx_datagrams >= 3, 5.0)
        assert inst.rx_dropped == 3
        assert inst.api_link.counters.rx_messages == 0
        assert not inst.vehicle.armed
        await sim.wait_ready(timeout_s=5.0)
        peer.send(mavlink.MAVLink_command_long_message(
            1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0), port)
        ack = await peer.wait_for("COMMAND_ACK")
        assert ack.result == mavlink.MAV_RESULT_ACCEPTED


def test_codec_decodes_two_frames_in_one_datagram() -> None:
    sender = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    data = heartbeat().pack(sender) + heartbeat().pack(sender)
    messages, bad = MavlinkCodec(1, 1).decode(data)
    assert [m.get_type() for m in messages] == ["HEARTBEAT", "HEARTBEAT"]
    assert bad == 0


async def test_speed_runs_sim_time_faster_than_wall_time() -> None:
    async with cluster(speed=5.0) as sim:
        start_wall = time.monotonic()
        start_sim = sim.instances[0].vehicle.now_s
        await asyncio.sleep(1.0)
        ratio = (sim.instances[0].vehicle.now_s - start_sim) / (time.monotonic() - start_wall)
        assert 3.5 < ratio <= 5.2


async def test_wait_ready_returns_after_boot(peer: UdpPeer) -> None:
    async with cluster(speed=5.0) as sim:
        await sim.wait_ready(timeout_s=5.0)
        assert sim.instances[0].vehicle.ready
        assert sim.instances[0].vehicle.now_s >= 3.0


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
