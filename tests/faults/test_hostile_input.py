"""Hostile input on both ends: malformed, unverifiable and spoofed MAVLink from a stranger.

The flood here is a share of bench/hostile_input.py's (which sends 100k datagrams to each
end); the rest checks the rules it relies on, one at a time: frames whose checksum cannot
be checked never choose a peer, the sim never follows a stranger while its partner talks,
the server's listening link keeps a system's address while that system talks.
"""

from __future__ import annotations

import asyncio
import random
import struct
from collections.abc import AsyncIterator
from typing import Any, cast

import pytest
from pymavlink.dialects.v20 import development as mavlink

from bench.hostile_input import HostileFrames, run_hostile
from server.link import Link
from sim.lib.events import MAVLINK_MSG_ID_REQUEST_EVENT
from sim.mavlink.endpoint import UdpLink, unknown_frame_crc_ok
from sim.process.runner import SimCluster
from tests.sim.conftest import PointMassAirframe, point_mass_defaults
from tests.waiting import holds_for, wait_for

LOOPBACK = "127.0.0.1"


class _Socket(asyncio.DatagramProtocol):
    """A UDP socket on an ephemeral loopback port that keeps what it receives."""

    def __init__(self) -> None:
        self.received: list[Any] = []
        self.datagrams = 0
        self.transport: asyncio.DatagramTransport | None = None
        self._mav = mavlink.MAVLink(None)
        self._mav.robust_parsing = True

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    @property
    def address(self) -> tuple[str, int]:
        assert self.transport is not None
        host, port = self.transport.get_extra_info("sockname")[:2]
        return str(host), int(port)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.datagrams += 1
        self.received.extend(self._mav.parse_buffer(data) or [])

    def sendto(self, data: bytes, port: int) -> None:
        assert self.transport is not None
        self.transport.sendto(data, (LOOPBACK, port))

    def of_type(self, name: str) -> list[Any]:
        return [m for m in self.received if m.get_type() == name]


async def _open_socket() -> _Socket:
    _, sock = await asyncio.get_running_loop().create_datagram_endpoint(
        _Socket, local_addr=(LOOPBACK, 0))
    return sock


@pytest.fixture
async def stranger() -> AsyncIterator[_Socket]:
    sock = await _open_socket()
    yield sock
    assert sock.transport is not None
    sock.transport.close()


def _cluster(**kwargs: Any) -> SimCluster:
    return SimCluster(airframe_factory=PointMassAirframe, defaults_factory=point_mass_defaults,
                      speed=5.0, **kwargs)


def _pack(msg: Any, sysid: int = 255, compid: int = 190) -> bytes:
    return bytes(msg.pack(mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)))


def _gcs_heartbeat() -> Any:
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID,
                                             0, 0, 0, 3)


def _vehicle_heartbeat() -> Any:
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR,
                                             mavlink.MAV_AUTOPILOT_PX4, 0, 0, 3, 3)


def _unknown_frames(count: int, seed: int = 5) -> list[bytes]:
    frames = HostileFrames(seed, to_server=False)
    return [frames._unknown_id() for _ in range(count)]


async def test_flood_of_both_ends_while_streaming_counts_everything_and_stalls_nothing() -> None:
    """1 200 hostile datagrams into each end (bench/hostile_input.py sends 100 000)."""
    result = await run_hostile(1200)
    assert result.server.counted == result.server.expected
    assert result.sim.counted == result.sim.expected
    assert sum(result.server.sent.values()) == sum(result.sim.sent.values()) == 1200
    # the vehicle's own judge of a stall: its offboard-loss failsafe (COM_OF_LOSS_T) never
    # fired; the stream's rate and gaps at the vehicle are bounded generously (50 Hz asked;
    # sender, server and vehicle share one process on a loaded machine here), the bench
    # reports them
    assert result.stayed_in_offboard
    assert result.setpoint_rate_hz > 20.0
    assert result.largest_setpoint_gap_s < 2.0
    assert result.sim_partner_kept
    assert result.vehicle_connected
    assert (result.disarm_ok, result.arm_again_ok, result.disarm_again_ok) == (True,) * 3
    assert result.sim_handler_errors == 0


async def test_random_frames_into_the_sims_port_do_not_take_its_telemetry(
    stranger: _Socket,
) -> None:
    """The bug measured before the fix: UNKNOWN_<id> parses of random bytes made the sim
    send its telemetry to whoever sent them, and the server lost the vehicle."""
    partner = await _open_socket()
    try:
        async with _cluster(api_port=partner.address[1]) as sim:
            inst = sim.instances[0]
            await wait_for(lambda: partner.of_type("HEARTBEAT"), 5.0, "telemetry to the partner")
            partner_sent = 0  # the partner only listens here
            frames = _unknown_frames(300)
            for start in range(0, len(frames), 30):  # a loopback socket's buffer holds these
                for frame in frames[start:start + 30]:
                    stranger.sendto(frame, inst.api_local_port)
                await wait_for(lambda n=start + 30: inst.api_link.counters.rx_unverified == n,
                               5.0, "the stranger's frames counted")
            rng = random.Random(13)  # and plain random bytes, markers and all
            for start in range(0, 300, 30):
                for _ in range(30):
                    stranger.sendto(rng.randbytes(rng.randint(1, 280)), inst.api_local_port)
                await wait_for(
                    lambda n=start + 330: inst.api_link.counters.rx_datagrams - partner_sent
                    >= n, 5.0, "random datagrams received")
            assert inst.api_link.counters.rx_messages == 0
            assert inst.api_link.remote == partner.address
            before = partner.datagrams
            await holds_for(lambda: stranger.datagrams == 0, 0.5, "nothing to the stranger")
            assert partner.datagrams > before
    finally:
        assert partner.transport is not None
        partner.transport.close()


async def test_with_a_remote_port_the_first_checked_sender_is_the_partner_for_good(
    stranger: _Socket,
) -> None:
    """PX4 sets its client source address once; a checked frame from anyone else is
    obeyed (MAVLink without signing) but never redirects the telemetry."""
    partner = await _open_socket()
    try:
        async with _cluster(api_port=partner.address[1]) as sim:
            inst = sim.instances[0]
            partner.sendto(_pack(_gcs_heartbeat()), inst.api_local_port)
            await wait_for(lambda: inst.api_link.counters.rx_messages == 1, 5.0, "partner heard")
            stranger.sendto(_pack(_gcs_heartbeat(), sysid=77), inst.api_local_port)
            await wait_for(lambda: inst.api_link.counters.rx_from_strangers == 1, 5.0,
                           "stranger heard")
            await holds_for(lambda: stranger.datagrams == 0, 0.5, "nothing to the stranger")
            assert inst.api_link.remote == partner.address
    finally:
        assert partner.transport is not None
        partner.transport.close()


async def test_without_a_remote_port_a_talking_partner_is_kept(stranger: _Socket) -> None:
    partner = await _open_socket()
    try:
        async with _cluster() as sim:
            inst = sim.instances[0]
            partner.sendto(_pack(_gcs_heartbeat()), inst.api_local_port)
            await wait_for(lambda: partner.of_type("HEARTBEAT"), 5.0, "answers to the partner")
            for frame in _unknown_frames(50):
                stranger.sendto(frame, inst.api_local_port)
            stranger.sendto(_pack(_gcs_heartbeat(), sysid=77), inst.api_local_port)
            await wait_for(lambda: inst.api_link.counters.rx_from_strangers == 1, 5.0,
                           "stranger heard")
            assert inst.api_link.counters.rx_unverified == 50
            await holds_for(lambda: stranger.datagrams == 0, 0.5, "nothing to the stranger")
    finally:
        assert partner.transport is not None
        partner.transport.close()


def test_a_request_event_is_checked_with_its_crc_extra_and_nothing_else_is() -> None:
    payload = struct.pack("<HHBB", 1, 2, 1, 1)  # packed by hand, as PX4 packs it
    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, 0, 255, 190,
                         MAVLINK_MSG_ID_REQUEST_EVENT & 0xFFFF, MAVLINK_MSG_ID_REQUEST_EVENT >> 16)
    crc = mavlink.x25crc(header[1:] + payload)
    crc.accumulate(bytes([33]))
    frame = bytearray(header + payload + struct.pack("<H", crc.crc))
    assert unknown_frame_crc_ok(bytes(frame))
    spoiled = bytearray(frame)
    spoiled[-1] ^= 0x01
    assert not unknown_frame_crc_ok(bytes(spoiled))
    other_id = bytearray(frame)
    other_id[7] = 0x9D  # id 413 with the same bytes: not an id the vehicle takes
    assert not unknown_frame_crc_ok(bytes(other_id))
    assert not unknown_frame_crc_ok(bytes(frame[:-1]))


def test_link_counts_unverified_separately_from_bad() -> None:
    link = UdpLink("api", 1, 1, lambda link, msg: None)
    link.datagram_received(_unknown_frames(1)[0], (LOOPBACK, 9))
    link.datagram_received(b"\x00garbage", (LOOPBACK, 9))
    assert (link.counters.rx_unverified, link.counters.rx_dropped) == (1, 1)
    assert link.remote is None


async def test_unverifiable_frames_neither_discover_nor_make_a_peer_of_the_server(
    stranger: _Socket,
) -> None:
    async with await Link.open(f"udpin:{LOOPBACK}:0") as link:
        assert link.local_address is not None
        port = link.local_address[1]
        frames = _unknown_frames(200)
        for start in range(0, len(frames), 25):
            for frame in frames[start:start + 25]:
                stranger.sendto(frame, port)
            await wait_for(lambda n=start + 25: link.stats().unverified_frames == n, 5.0,
                           "counted")
        assert link.vehicles == {}
        assert link.stats().frames_in == 0
        # no GCS HEARTBEAT goes to someone who never sent a checked frame
        await holds_for(lambda: stranger.datagrams == 0, 1.2, "nothing to the stranger")


async def test_a_stranger_claiming_a_talking_vehicle_is_dropped_not_followed(
    stranger: _Socket,
) -> None:
    vehicle = await _open_socket()
    try:
        async with await Link.open(f"udpin:{LOOPBACK}:0") as link:
            assert link.local_address is not None
            port = link.local_address[1]
            vehicle.sendto(_pack(_vehicle_heartbeat(), sysid=1, compid=1), port)
            await wait_for(lambda: 1 in link.vehicles, 5.0, "discovery")
            stranger.sendto(_pack(_vehicle_heartbeat(), sysid=1, compid=1), port)
            await wait_for(lambda: link.stats().bad_frames == 1, 5.0, "the claim dropped")
            link.send(mavlink.MAVLink_command_long_message(
                1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
            await wait_for(lambda: vehicle.of_type("COMMAND_LONG"), 5.0, "command to the vehicle")
            assert not stranger.of_type("COMMAND_LONG")
    finally:
        assert vehicle.transport is not None
        vehicle.transport.close()
