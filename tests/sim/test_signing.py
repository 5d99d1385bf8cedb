"""The simulated vehicle enforces MAVLink 2 signing as PX4's main branch does: over real
UDP on loopback, from plain pymavlink sockets (an unsigned, a wrong-key and a right-key
sender), with the key in PX4's 40-byte file per instance."""

from __future__ import annotations

import asyncio
import os
import secrets
import struct
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any, cast

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.mavlink.signing import MAVLINK_SECRET_FILE
from sim.process.runner import SimCluster
from tests.sim.conftest import PointMassAirframe, point_mass_defaults
from tests.waiting import holds_for, wait_for

SIGNING_EPOCH_UNIX_S = 1_420_070_400
ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM


def now_ticks() -> int:
    return int((time.time() - SIGNING_EPOCH_UNIX_S) * 100_000)


class Sender(asyncio.DatagramProtocol):
    """A GCS on an ephemeral loopback port: signs with ``key`` (None: sends unsigned)."""

    def __init__(self, key: bytes | None = None, link_id: int = 0) -> None:
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        if key is not None:
            self.mav.signing.secret_key = key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.link_id = link_id
            self.mav.signing.timestamp = now_ticks()
        self.received: list[Any] = []
        self.frames: list[bytes] = []
        self._transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        # read without a key: the signature is looked at in the tests themselves
        self.received.extend(mavlink.MAVLink(None).parse_buffer(data) or [])

    def send(self, msg: Any, port: int) -> bytes:
        frame = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        self.send_bytes(frame, port)
        return frame

    def send_bytes(self, frame: bytes, port: int) -> None:
        assert self._transport is not None
        self._transport.sendto(frame, ("127.0.0.1", port))

    def acks(self) -> list[Any]:
        return [m for m in self.received if m.get_type() == "COMMAND_ACK"]

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()


async def open_sender(key: bytes | None = None, link_id: int = 0) -> Sender:
    _, sender = await asyncio.get_running_loop().create_datagram_endpoint(
        lambda: Sender(key, link_id), local_addr=("127.0.0.1", 0)
    )
    return sender


def arm(value: int = 1) -> Any:
    return mavlink.MAVLink_command_long_message(1, 1, ARM, 0, value, 0, 0, 0, 0, 0, 0)


def setup_signing(key: bytes, timestamp: int, target_system: int = 1) -> Any:
    return mavlink.MAVLink_setup_signing_message(target_system, 1, list(key), timestamp)


def write_key_file(signing_dir: Path, key: bytes, timestamp: int, instance: int = 0) -> Path:
    path = signing_dir / str(instance) / MAVLINK_SECRET_FILE
    path.parent.mkdir(parents=True)
    path.write_bytes(key + struct.pack("<Q", timestamp))
    return path


@pytest.fixture
async def signed_sim(tmp_path: Path) -> AsyncIterator[tuple[SimCluster, bytes]]:
    """A ready simulated quad whose key file was provisioned before it started."""
    key = secrets.token_bytes(32)
    write_key_file(tmp_path, key, now_ticks())
    async with SimCluster(airframe_factory=PointMassAirframe,
                          defaults_factory=point_mass_defaults, speed=5.0,
                          signing_dir=tmp_path) as sim:
        await sim.wait_ready(timeout_s=10.0)
        yield sim, key


async def test_unsigned_and_wrong_key_senders_cannot_arm_but_the_key_holder_can(
    signed_sim: tuple[SimCluster, bytes],
) -> None:
    sim, key = signed_sim
    inst = sim.instances[0]
    port = inst.api_local_port
    unsigned, wrong, right = (await open_sender(), await open_sender(secrets.token_bytes(32)),
                              await open_sender(key))
    try:
        unsigned.send(arm(), port)
        wrong.send(arm(), port)
        await wait_for(lambda: inst.signing is not None and inst.signing.rejected >= 2, 5.0,
                       "both refused")
        await holds_for(lambda: not inst.vehicle.armed and not unsigned.acks()
                        and not wrong.acks(), 0.3, "nobody armed it")
        right.send(arm(), port)
        await wait_for(lambda: right.acks(), 5.0, "an ack to the key holder")
        assert right.acks()[0].result == mavlink.MAV_RESULT_ACCEPTED
        assert inst.vehicle.armed
        # what the vehicle sends is signed, and verifies with the key
        checker = mavlink.MAVLink(None)
        checker.signing.secret_key = key
        assert all(m.get_msgbuf()[2] & 1 for m in right.received)
        assert checker.check_signature(bytearray(right.acks()[0].get_msgbuf()), 1, 1)
    finally:
        for sender in (unsigned, wrong, right):
            sender.close()


async def test_a_replayed_signed_arm_is_rejected(signed_sim: tuple[SimCluster, bytes]) -> None:
    sim, key = signed_sim
    inst = sim.instances[0]
    port = inst.api_local_port
    right = await open_sender(key)
    try:
        recorded_arm = right.send(arm(), port)
        await wait_for(lambda: inst.vehicle.armed, 5.0, "armed")
        right.send(arm(0), port)
        await wait_for(lambda: not inst.vehicle.armed, 5.0, "disarmed")
        rejected = inst.signing.rejected if inst.signing else 0
        right.send_bytes(recorded_arm, port)  # the same bytes again: an old timestamp
        await wait_for(lambda: inst.signing is not None and inst.signing.rejected > rejected,
                       5.0, "the replay refused")
        await holds_for(lambda: not inst.vehicle.armed, 0.3, "still disarmed")
    finally:
        right.close()


async def test_heartbeat_is_accepted_unsigned_and_answered_signed(
    signed_sim: tuple[SimCluster, bytes],
) -> None:
    sim, _key = signed_sim
    unsigned = await open_sender()
    try:
        unsigned.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3),
                      sim.instances[0].api_local_port)
        # the vehicle now talks to whoever spoke (allowlisted HEARTBEAT), signed
        await wait_for(lambda: any(m.get_type() == "HEARTBEAT" for m in unsigned.received),
                       5.0, "telemetry")
        assert all(m.get_msgbuf()[2] & 1 for m in unsigned.received)
    finally:
        unsigned.close()


async def test_setup_signing_sets_rotates_and_clears_the_key_and_persists_it(
    tmp_path: Path,
) -> None:
    first, second = secrets.token_bytes(32), secrets.token_bytes(32)
    key_file = tmp_path / "0" / MAVLINK_SECRET_FILE
    async with SimCluster(airframe_factory=PointMassAirframe,
                          defaults_factory=point_mass_defaults, speed=5.0,
                          signing_dir=tmp_path) as sim:
        inst = sim.instances[0]
        signing = inst.signing
        assert signing is not None
        assert not signing.enabled
        port = inst.api_local_port
        plain = await open_sender()
        try:
            ts = now_ticks()
            plain.send(setup_signing(first, ts), port)  # no key yet: taken unsigned
            await wait_for(lambda: signing.secret_key == first, 5.0, "first key")
            assert key_file.read_bytes() == first + struct.pack("<Q", ts)
            assert os.stat(key_file).st_mode & 0o777 == 0o600
            assert os.stat(key_file.parent).st_mode & 0o777 == 0o700
            # with a key, an unsigned SETUP_SIGNING is refused like any unsigned message
            plain.send(setup_signing(second, ts + 1), port)
            await wait_for(lambda: signing.rejected >= 1, 5.0, "unsigned refused")
            assert signing.secret_key == first
        finally:
            plain.close()
        holder = await open_sender(first)
        try:
            holder.send(setup_signing(second, now_ticks(), target_system=7), port)
            await wait_for(lambda: signing.setup_refused == 1, 5.0, "another's key ignored")
            holder.send(setup_signing(second, now_ticks()), port)
            await wait_for(lambda: signing.secret_key == second, 5.0, "rotated")
        finally:
            holder.close()
        rotated = await open_sender(second)
        try:
            rotated.send(setup_signing(bytes(32), 0), port)  # all zero: signing off
            await wait_for(lambda: not signing.enabled, 5.0, "cleared")
            assert key_file.read_bytes() == bytes(40)
        finally:
            rotated.close()


async def test_setup_signing_is_ignored_while_armed(signed_sim: tuple[SimCluster, bytes]) -> None:
    sim, key = signed_sim
    inst = sim.instances[0]
    holder = await open_sender(key)
    try:
        holder.send(arm(), inst.api_local_port)
        await wait_for(lambda: inst.vehicle.armed, 5.0, "armed")
        holder.send(setup_signing(secrets.token_bytes(32), now_ticks()), inst.api_local_port)
        await wait_for(lambda: inst.signing is not None and inst.signing.setup_refused == 1,
                       5.0, "refused while armed")
        assert inst.signing is not None
        assert inst.signing.secret_key == key
    finally:
        holder.close()


async def test_a_restarted_vehicle_keeps_its_key_and_signs_past_its_last_timestamp(
    tmp_path: Path,
) -> None:
    key = secrets.token_bytes(32)
    future = now_ticks() + 3_600 * 100_000  # an hour ahead: as if the clock went back
    key_file = write_key_file(tmp_path, key, future)
    async with SimCluster(airframe_factory=PointMassAirframe,
                          defaults_factory=point_mass_defaults, speed=5.0,
                          signing_dir=tmp_path) as sim:
        peer = await open_sender(key)
        try:
            peer.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3),
                      sim.instances[0].api_local_port)
            await wait_for(lambda: peer.received, 5.0, "telemetry")
            low, high = struct.unpack("<IH", peer.received[0].get_msgbuf()[-12:-6])
            assert low + (high << 32) >= future
        finally:
            peer.close()
    # a graceful stop wrote the timestamp reached back
    (stored,) = struct.unpack_from("<Q", key_file.read_bytes(), 32)
    assert key_file.read_bytes()[:32] == key
    assert stored > future
