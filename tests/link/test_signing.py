"""MAVLink 2 signing on the server's link, against the simulated vehicle over real UDP:
provisioning with SETUP_SIGNING, rotation without losing the vehicle, switching off,
counters of rejected frames, the replay window, timestamps persisted across restarts,
and the key kept out of the tlog and the logs."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import secrets
from collections.abc import AsyncIterator
from pathlib import Path
from typing import TypeVar, cast

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.signing import LinkSigning
from server.link.codec.signing_keys import (
    PERSIST_MARGIN_TICKS,
    SigningKeyError,
    SigningKeyStore,
    signing_timestamp,
)
from server.link.codec.signing_provision import provision
from server.link.codec.tlog import iter_tlog
from server.link.link import Link
from server.link.vehicle import Vehicle
from server.simproc import SimProcess
from sim.process.runner import SimCluster
from tests.sim.conftest import PointMassAirframe, point_mass_defaults
from tests.waiting import wait_for

HEARTBEAT = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3)


@contextlib.asynccontextmanager
async def sim_and_link(
    tmp_path: Path, *, log_dir: Path | None = None
) -> AsyncIterator[tuple[SimCluster, Link, Vehicle]]:
    async with SimCluster(airframe_factory=PointMassAirframe,
                          defaults_factory=point_mass_defaults, speed=5.0,
                          signing_dir=tmp_path / "sim") as sim:
        store = SigningKeyStore(tmp_path / "keys" / "signing.key")
        link = await Link.open(f"udpout:127.0.0.1:{sim.instances[0].api_local_port}",
                               log_dir=log_dir, signing_store=store)
        try:
            await wait_for(lambda: 1 in link.vehicles, 10.0, "discovery")
            yield sim, link, link.vehicles[1]
        finally:
            await link.close()


@contextlib.asynccontextmanager
async def signed_link_on_loopback(tmp_path: Path) -> AsyncIterator[tuple[bytes, Link, int]]:
    """A link listening on a loopback port with a fresh signing key: the key, the link and
    its port."""
    key = secrets.token_bytes(32)
    store = SigningKeyStore(tmp_path / "signing.key")
    store.replace_key(key)
    link = await Link.open("udpin:127.0.0.1:0", log_dir=None, signing_store=store)
    try:
        assert link.local_address is not None
        yield key, link, link.local_address[1]
    finally:
        await link.close()


def signing_of(link: Link) -> dict[str, object]:
    stats = link.stats().signing
    assert stats is not None
    return vars(stats)


async def test_provisioned_key_signs_both_ways_and_rotation_keeps_the_vehicle(
    tmp_path: Path,
) -> None:
    async with sim_and_link(tmp_path) as (sim, link, vehicle):
        inst = sim.instances[0]
        assert inst.signing is not None
        assert signing_of(link)["enabled"] is False
        events = vehicle.subscribe_events()
        first = secrets.token_bytes(32)
        await provision(link, [1], first)
        assert inst.signing.secret_key == first
        assert signing_of(link)["vehicles_signed"] is True
        # commands now go signed and the vehicle answers signed
        await sim.wait_ready(timeout_s=10.0)
        result = await vehicle.arm()
        assert result.ok, result
        await vehicle.disarm(force=True)
        second = secrets.token_bytes(32)
        await wait_for(lambda: not inst.vehicle.armed, 5.0, "disarmed")
        await provision(link, [1], second)
        assert inst.signing.secret_key == second
        signed_before = signing_of(link)["signed_in"]
        await wait_for(lambda: signing_of(link)["signed_in"] > signed_before, 5.0, "more")
        assert vehicle.connected
        lost = [e for e in _drain(events) if e.kind == "connection"]
        assert lost == [], "the vehicle was lost during the rotation"
        assert signing_of(link)["provisions"] == 2


async def test_switching_signing_off_leaves_both_ends_unsigned(tmp_path: Path) -> None:
    async with sim_and_link(tmp_path) as (sim, link, _vehicle):
        await provision(link, [1], secrets.token_bytes(32))
        await provision(link, [1], None)
        signing = sim.instances[0].signing
        assert signing is not None
        assert not signing.enabled
        assert not link.signing.enabled
        unsigned_before = signing_of(link)["unsigned_in"]
        await wait_for(lambda: signing_of(link)["unsigned_in"] > unsigned_before, 5.0, "more")


async def test_setup_signing_and_the_key_never_reach_the_tlog_or_the_log(
    tmp_path: Path, caplog: pytest.LogCaptureFixture,
) -> None:
    for name in ("server", "sim"):
        caplog.set_level(logging.DEBUG, logger=name)
    key = secrets.token_bytes(32)
    async with sim_and_link(tmp_path, log_dir=tmp_path / "logs") as (_sim, link, _vehicle):
        await provision(link, [1], key)
        tlog = link.tlog_path
    assert tlog is not None
    data = tlog.read_bytes()
    text = caplog.text
    assert "SETUP_SIGNING" in text or "signing" in text  # the logging was captured
    assert key not in data
    assert key.hex() not in text
    assert str(list(key))[1:-1] not in text
    ids = set()
    for _t, frame in iter_tlog(tlog):
        ids.add(frame[7] | frame[8] << 8 | frame[9] << 16 if frame[0] == 0xFD else frame[5])
    assert mavlink.MAVLINK_MSG_ID_HEARTBEAT in ids
    assert mavlink.MAVLINK_MSG_ID_SETUP_SIGNING not in ids


async def test_the_key_file_is_owner_only_and_a_restart_resumes_past_the_used_timestamp(
    tmp_path: Path,
) -> None:
    store = SigningKeyStore(tmp_path / "signing.key")
    store.replace_key(secrets.token_bytes(32))
    assert os.stat(store.key_file).st_mode & 0o777 == 0o600
    signing = LinkSigning(SigningKeyStore(store.key_file))
    # as if the clock had gone back an hour after these frames were signed
    used = signing_timestamp() + 3_600 * 100_000
    signing.state.timestamp = used
    await signing.close()
    restarted = LinkSigning(SigningKeyStore(store.key_file))
    assert restarted.enabled
    assert restarted.state.timestamp >= used + PERSIST_MARGIN_TICKS
    assert os.stat(store.timestamp_file).st_mode & 0o777 == 0o600


class Peer(asyncio.DatagramProtocol):
    """A vehicle stand-in that signs (or not) with a key of its choosing."""

    def __init__(self) -> None:
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def codec(self, key: bytes | None, timestamp: int | None = None) -> mavlink.MAVLink:
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        if key is not None:
            mav.signing.secret_key = key
            mav.signing.sign_outgoing = True
            mav.signing.timestamp = timestamp or signing_timestamp()
        return mav

    def send(self, frame: bytes, port: int) -> None:
        assert self.transport is not None
        self.transport.sendto(frame, ("127.0.0.1", port))


async def test_link_rejects_unsigned_wrong_key_and_replayed_frames_and_counts_them(
    tmp_path: Path,
) -> None:
    async with signed_link_on_loopback(tmp_path) as (key, link, port):
        transport, peer = await open_peer(Peer)
        try:
            good = peer.codec(key)
            status = mavlink.MAVLink_sys_status_message(*([0] * 13))
            recorded = bytes(status.pack(good))
            peer.send(recorded, port)
            await wait_for(lambda: signing_of(link)["signed_in"] == 1, 5.0, "signed frame in")
            peer.send(recorded, port)  # replayed
            peer.send(bytes(status.pack(peer.codec(secrets.token_bytes(32)))), port)  # wrong key
            peer.send(bytes(status.pack(peer.codec(None))), port)  # unsigned
            peer.send(bytes(HEARTBEAT.pack(peer.codec(None))), port)  # unsigned, allowlisted
            await wait_for(lambda: signing_of(link)["rejected"] == 3, 5.0, "three rejected")
            stats = signing_of(link)
            assert (stats["rejected_replay"], stats["rejected_bad_signature"],
                    stats["rejected_unsigned"]) == (1, 1, 1)
            await wait_for(lambda: 1 in link.vehicles, 5.0, "found by its unsigned HEARTBEAT")
            assert link.stats().bad_frames == 0  # refused frames are not broken ones
            # a forged frame from a far-future timestamp must not make the genuine stream stale
            forged = peer.codec(secrets.token_bytes(32), signing_timestamp() + 10**12)
            peer.send(bytes(status.pack(forged)), port)
            peer.send(bytes(status.pack(good)), port)
            await wait_for(lambda: signing_of(link)["signed_in"] == 2, 5.0, "genuine one taken")
        finally:
            transport.close()


def _drain(queue: asyncio.Queue[object]) -> list[object]:  # type: ignore[type-arg]
    items = []
    while not queue.empty():
        items.append(queue.get_nowait())
    return items




def test_a_bad_key_file_is_named_without_its_content(tmp_path: Path) -> None:
    key_file = tmp_path / "signing.key"
    key_file.write_text("secret-but-not-a-key\n")
    with pytest.raises(SigningKeyError) as raised:
        SigningKeyStore(key_file)
    assert str(key_file) in str(raised.value)
    assert "secret-but-not-a-key" not in str(raised.value)


PeerT = TypeVar("PeerT", bound="Peer")


async def open_peer(kind: type[PeerT]) -> tuple[asyncio.DatagramTransport, PeerT]:
    return await asyncio.get_running_loop().create_datagram_endpoint(
        kind, local_addr=("127.0.0.1", 0)
    )


class Recorder(Peer):
    def __init__(self) -> None:
        super().__init__()
        self.frames: list[bytes] = []

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.frames.append(data)


async def test_an_unsigned_spoof_of_the_vehicle_does_not_redirect_the_links_answers(
    tmp_path: Path,
) -> None:
    async with signed_link_on_loopback(tmp_path) as (key, link, port):
        t1, vehicle = await open_peer(Recorder)
        t2, spoofer = await open_peer(Recorder)
        try:
            status = mavlink.MAVLink_sys_status_message(*([0] * 13))
            vehicle.send(bytes(status.pack(vehicle.codec(key))), port)
            await wait_for(lambda: signing_of(link)["signed_in"] == 1, 5.0, "the vehicle heard")
            spoofer.send(bytes(status.pack(spoofer.codec(None))), port)  # claims to be system 1
            await wait_for(lambda: signing_of(link)["rejected_unsigned"] == 1, 5.0, "refused")
            link.send(link.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
            await wait_for(lambda: len(vehicle.frames) >= 1, 5.0, "the command at the vehicle")
            assert not [f for f in spoofer.frames if f[7] == 76]  # no COMMAND_LONG to the spoofer
        finally:
            t1.close()
            t2.close()


async def test_sim_process_with_a_signing_dir_talks_signed_with_the_same_key(
    tmp_path: Path,
) -> None:
    """`python -m sim --signing-dir` (what the server starts) loads PX4's key file."""
    key = secrets.token_bytes(32)
    key_file = tmp_path / "sim" / "0" / "mavlink" / "mavlink-signing-key.bin"
    key_file.parent.mkdir(parents=True)
    key_file.write_bytes(key + signing_timestamp().to_bytes(8, "little"))
    store = SigningKeyStore(tmp_path / "signing.key")
    store.replace_key(key)
    sim = SimProcess(signing_dir=tmp_path / "sim")
    instances = await sim.start()
    try:
        link = await Link.open(instances[0].url, log_dir=None, signing_store=store)
        try:
            await wait_for(lambda: signing_of(link)["vehicles_signed"] is True, 20.0,
                           "signed both ways")
            assert signing_of(link)["rejected"] == 0
        finally:
            await link.close()
    finally:
        await sim.stop()
