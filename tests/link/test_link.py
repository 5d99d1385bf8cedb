"""The Link against scripted MAVLink peers on 127.0.0.1, with stand-in vehicles."""

import asyncio
import contextlib
import os
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any, cast

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import development as mavlink

from server.link import Link
from server.link.codec.tlog import iter_tlog
from server.link.transports.udp import LINK_RECEIVE_BUFFER_BYTES
from tests.waiting import wait_for as _until


class _StandInVehicle:
    """Records what the link hands a vehicle, as the contract describes it."""

    def __init__(self, *, link: Link, sysid: int, compid: int,
                 heartbeat: mavlink.MAVLink_message) -> None:
        self.link = link
        self.sysid = sysid
        self.compid = compid
        self.first_heartbeat = heartbeat
        self.messages: list[mavlink.MAVLink_message] = []
        self.connected_calls: list[bool] = []

    def handle_message(self, msg: mavlink.MAVLink_message) -> None:
        self.messages.append(msg)

    def set_connected(self, connected: bool, reason: str | None = None, **_: object) -> None:
        self.connected_calls.append(connected)

    def types(self) -> list[str]:
        return [m.get_type() for m in self.messages]


class _Peer(asyncio.DatagramProtocol):
    """A scripted MAVLink system on UDP: sends what the test says, keeps what arrives."""

    def __init__(self) -> None:
        self.endpoint: asyncio.DatagramTransport | None = None
        self.decoder = mavlink.MAVLink(None)
        self.received: list[tuple[float, mavlink.MAVLink_message]] = []

    def datagram_received(self, data: bytes, addr: Any) -> None:
        for msg in self.decoder.parse_buffer(data) or []:
            self.received.append((time.monotonic(), msg))

    @property
    def port(self) -> int:
        assert self.endpoint is not None
        return int(self.endpoint.get_extra_info("sockname")[1])

    def send(self, msg: mavlink.MAVLink_message, link: Link, *, sysid: int = 1, compid: int = 1,
             seq: int = 0) -> None:
        mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        mav.seq = seq
        assert self.endpoint is not None
        assert link.local_address is not None
        self.endpoint.sendto(bytes(msg.pack(mav)), ("127.0.0.1", link.local_address[1]))

    def heartbeats_from(self, sysid: int) -> list[tuple[float, mavlink.MAVLink_message]]:
        return [(t, m) for t, m in self.received
                if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == sysid]


@contextlib.asynccontextmanager
async def _peer() -> AsyncIterator[_Peer]:
    peer = _Peer()
    peer.endpoint, _ = await asyncio.get_running_loop().create_datagram_endpoint(
        lambda: peer, local_addr=("127.0.0.1", 0))
    try:
        yield peer
    finally:
        peer.endpoint.close()


def _heartbeat(mav_type: int = mavlink.MAV_TYPE_QUADROTOR,
               autopilot: int = mavlink.MAV_AUTOPILOT_PX4) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_heartbeat_message(mav_type, autopilot, 0, 0, 0, 3)


def _statustext(text: str) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_statustext_message(6, text.encode())


@contextlib.asynccontextmanager
async def _udpin_link(**kwargs: Any) -> AsyncIterator[Link]:
    link = await Link.open("udpin:127.0.0.1:0", vehicle_factory=cast(Any, _StandInVehicle),
                           **kwargs)
    try:
        yield link
    finally:
        await link.close()


def _stand_in(link: Link, sysid: int) -> _StandInVehicle:
    vehicle = link.vehicles[sysid]
    assert isinstance(vehicle, _StandInVehicle)
    return vehicle


async def test_vehicles_are_discovered_only_from_autopilot_heartbeats() -> None:
    async with _udpin_link() as link, _peer() as peer:
        announcements = link.subscribe_vehicles()
        peer.send(_heartbeat(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID), link, sysid=7)
        peer.send(_heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER), link, sysid=8)
        peer.send(_heartbeat(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_INVALID), link,
                  sysid=9)
        peer.send(_heartbeat(), link, sysid=10, compid=100)  # a camera, not the autopilot
        peer.send(_heartbeat(mavlink.MAV_TYPE_VTOL_TILTROTOR), link, sysid=2)
        peer.send(_heartbeat(), link, sysid=3)
        first = await asyncio.wait_for(announcements.get(), 5.0)
        second = await asyncio.wait_for(announcements.get(), 5.0)
        assert (first.sysid, second.sysid) == (2, 3)
        assert sorted(link.vehicles) == [2, 3]
        assert _stand_in(link, 2).first_heartbeat.type == mavlink.MAV_TYPE_VTOL_TILTROTOR
        assert (first.compid, first.link) == (1, link)
        late = link.subscribe_vehicles()
        assert sorted([late.get_nowait().sysid, late.get_nowait().sysid]) == [2, 3]
        link.unsubscribe_vehicles(late)
        peer.send(_heartbeat(), link, sysid=4)
        assert (await asyncio.wait_for(announcements.get(), 5.0)).sysid == 4
        assert late.empty()


async def test_messages_go_to_the_vehicle_of_their_source_system_only() -> None:
    async with _udpin_link() as link, _peer() as peer:
        peer.send(_heartbeat(), link, sysid=1)
        peer.send(_heartbeat(), link, sysid=2)
        await _until(lambda: len(link.vehicles) == 2)
        peer.send(_statustext("one"), link, sysid=1, compid=1, seq=1)
        peer.send(_statustext("gimbal"), link, sysid=1, compid=154)
        peer.send(_statustext("two"), link, sysid=2, compid=1, seq=1)
        await _until(lambda: len(_stand_in(link, 1).messages) == 3)
        await _until(lambda: len(_stand_in(link, 2).messages) == 2)
        one = _stand_in(link, 1)
        assert one.types() == ["HEARTBEAT", "STATUSTEXT", "STATUSTEXT"]
        assert [m.text for m in one.messages[1:]] == ["one", "gimbal"]
        assert _stand_in(link, 2).messages[1].text == "two"


async def test_a_failing_vehicle_handler_does_not_stop_the_link() -> None:
    async with _udpin_link() as link, _peer() as peer:
        peer.send(_heartbeat(), link, sysid=1)
        await _until(lambda: 1 in link.vehicles)
        vehicle = _stand_in(link, 1)

        def explode(msg: mavlink.MAVLink_message) -> None:
            vehicle.messages.append(msg)
            raise RuntimeError("vehicle bug")

        vehicle.handle_message = explode  # type: ignore[method-assign]
        peer.send(_statustext("a"), link, seq=1)
        peer.send(_statustext("b"), link, seq=2)
        await _until(lambda: len(vehicle.messages) == 3)


async def test_vehicle_is_lost_after_heartbeat_timeout_and_back_on_the_next() -> None:
    async with _udpin_link(heartbeat_timeout_s=0.6) as link, _peer() as peer:
        peer.send(_heartbeat(), link)
        await _until(lambda: 1 in link.vehicles)
        assert link.stats().connected
        vehicle = _stand_in(link, 1)
        await _until(lambda: vehicle.connected_calls == [False], timeout_s=3.0)
        stats = link.stats()
        assert not stats.connected
        assert stats.last_heartbeat_age_s is not None
        assert stats.last_heartbeat_age_s > 0.6
        peer.send(_heartbeat(), link, seq=1)
        await _until(lambda: vehicle.connected_calls == [False, True])
        assert link.stats().connected


async def test_gcs_heartbeat_goes_out_at_1_hz_with_configured_ids() -> None:
    async with _peer() as peer:
        link = await Link.open(f"udpout:127.0.0.1:{peer.port}", gcs_sysid=250, gcs_compid=191)
        try:
            await _until(lambda: len(peer.heartbeats_from(250)) >= 2, timeout_s=4.0)
        finally:
            await link.close()
    (first_s, first), (second_s, _) = peer.heartbeats_from(250)[:2]
    assert first.get_srcComponent() == 191
    assert (first.type, first.autopilot) == (mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID)
    assert 0.7 < second_s - first_s < 1.5


async def test_send_uses_link_ids_and_consecutive_sequence_in_mavlink2() -> None:
    async with _peer() as peer:
        link = await Link.open(f"udpout:127.0.0.1:{peer.port}", gcs_sysid=42, gcs_compid=190)
        try:
            for _ in range(3):
                link.send(link.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
            await _until(lambda: sum(m.get_type() == "COMMAND_LONG"
                                     for _, m in peer.received) == 3)
        finally:
            await link.close()
    frames = [m for _, m in peer.received]
    seqs = [m.get_seq() for m in frames]
    assert seqs == list(range(len(frames)))  # heartbeats and commands share one counter
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in frames} == {(42, 190)}
    assert all(m.get_msgbuf()[0] == mavlink.PROTOCOL_MARKER_V2 for m in frames)


async def test_send_before_anyone_spoke_to_udpin_is_dropped_and_counted() -> None:
    async with _udpin_link() as link:
        link.send(link.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        stats = link.stats()
        assert (stats.frames_out, stats.bytes_out) == (0, 0)
        assert link.frames_dropped_out >= 1


async def test_stats_count_frames_bytes_gaps_and_bad_frames() -> None:
    async with _udpin_link() as link, _peer() as peer:
        assert link.stats().last_heartbeat_age_s is None
        for seq in (0, 1, 5, 6):  # 2, 3, 4 never sent: three lost
            peer.send(_heartbeat(), link, seq=seq)
        peer.send(_statustext("x"), link, compid=191, seq=200)  # another component: no gap
        assert peer.endpoint is not None
        assert link.local_address is not None
        peer.endpoint.sendto(b"\x01\x02 not mavlink", ("127.0.0.1", link.local_address[1]))
        await _until(lambda: link.stats().frames_in == 5 and link.stats().bad_frames == 1)
        await _until(lambda: link.stats().frames_out >= 1)  # our heartbeat, now a peer is known
        stats = link.stats()
        assert stats.lost_frames == 3
        assert stats.bytes_in > 5 * 12
        assert stats.bytes_out >= 21
        assert stats.url == "udpin:127.0.0.1:0"
        assert stats.last_heartbeat_age_s is not None
        assert stats.last_heartbeat_age_s < 3.0
        assert stats.reconnects == 0


def _receive_buffer_cap_bytes() -> int:
    return int(Path("/proc/sys/net/core/rmem_max").read_text())


async def test_a_server_held_off_its_loop_loses_none_of_a_vehicles_frames() -> None:
    """10 s of PX4's ~200 frames/s arrive while the link cannot read (its loop busy, as on a
    loaded laptop): each is delivered once it can, none lost (the OS's default buffer keeps
    ~256 datagrams and drops the rest)."""
    if _receive_buffer_cap_bytes() < LINK_RECEIVE_BUFFER_BYTES:
        pytest.skip("net.core.rmem_max caps a socket's receive buffer below what the link asks")
    frames = 2000
    async with _udpin_link() as link, _peer() as peer:
        for seq in range(frames):  # sent without yielding: the link reads none of them yet
            peer.send(_heartbeat(), link, seq=seq % 256)
        await _until(lambda: link.stats().frames_in == frames, timeout_s=30.0)
        assert link.stats().lost_frames == 0


async def test_tlog_records_both_directions_readable_by_pymavlink(tmp_path: Path) -> None:
    async with _udpin_link(log_dir=tmp_path, name="router") as link, _peer() as peer:
        peer.send(_heartbeat(), link)
        await _until(lambda: 1 in link.vehicles)
        link.send(link.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        path = link.tlog_path
    assert path is not None
    assert path.parent == tmp_path
    assert path.name.endswith("-router.tlog")
    conn = mavutil.mavlink_connection(str(path), dialect="development")
    seen = set()
    while (msg := conn.recv_match(blocking=False)) is not None:
        seen.add((msg.get_srcSystem(), msg.get_type()))
    conn.close()
    assert {(1, "HEARTBEAT"), (255, "HEARTBEAT"), (255, "COMMAND_LONG")} <= seen


async def test_several_links_run_side_by_side() -> None:
    async with _udpin_link() as one, _udpin_link() as two, _peer() as peer:
        peer.send(_heartbeat(), one, sysid=1)
        peer.send(_heartbeat(), two, sysid=2)
        await _until(lambda: list(one.vehicles) == [1] and list(two.vehicles) == [2])


async def test_frames_of_unknown_message_ids_are_counted_and_dropped_unrecorded(
    tmp_path: Path,
) -> None:
    """An id outside the dialect has a checksum nobody can check: its header is not
    trusted (no sequence gap), it is not dispatched, not recorded, and counted apart."""
    async with _udpin_link(log_dir=tmp_path) as link, _peer() as peer:
        peer.send(_heartbeat(), link, seq=0)
        await _until(lambda: 1 in link.vehicles)
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        mav.seq = 3  # 1 and 2 would be lost, were the header believed
        unknown = bytearray(_statustext("x").pack(mav))
        unknown[7:10] = (0xFFFF00).to_bytes(3, "little")  # a message id no dialect has
        assert peer.endpoint is not None
        assert link.local_address is not None
        peer.endpoint.sendto(bytes(unknown), ("127.0.0.1", link.local_address[1]))
        await _until(lambda: link.stats().unverified_frames == 1)
        assert link.stats().frames_in == 1
        assert link.stats().lost_frames == 0
        assert link.stats().bad_frames == 0
        assert _stand_in(link, 1).types() == ["HEARTBEAT"]
        path = link.tlog_path
    assert path is not None
    assert not any(frame == bytes(unknown) for _, frame in iter_tlog(path))


async def test_a_port_already_taken_fails_open_and_leaves_no_tlog(tmp_path: Path) -> None:
    async with _udpin_link() as first:
        assert first.local_address is not None
        taken = f"udpin:127.0.0.1:{first.local_address[1]}"
        with pytest.raises(OSError, match="in use"):
            await Link.open(taken, log_dir=tmp_path)
    assert os.listdir(tmp_path) == []


async def test_a_frame_racing_a_handover_to_the_sender_process_goes_through_it() -> None:
    """A frame whose sender looked before the link was handed to the sender process, and
    took the send lock after, is not written by the link with a sequence number the process
    was given too (a repeated number reads as 255 frames lost at PX4): it goes through the
    process."""
    async with _udpin_link() as link:
        handover = cast(Any, link)._handover
        real_send = handover.send
        through_process: list[mavlink.MAVLink_message] = []

        def racing_send(msg: mavlink.MAVLink_message, target: int | None) -> bool | None:
            if handover.out is None and not through_process:
                handover.out = object()  # the hand-over lands between the look and the lock
                through_process.append(msg)
                return None  # this look still saw no process
            if handover.out is not None:
                through_process.append(msg)
                return True
            return cast(bool | None, real_send(msg, target))

        handover.send = racing_send
        seq_before, frames_before = link.mav.seq, cast(Any, link)._frames_out
        link.send(_statustext("racing"))
        assert link.mav.seq == seq_before, "the link numbered a frame the process numbers"
        assert cast(Any, link)._frames_out == frames_before
        assert len(through_process) == 2  # looked once before the hand-over, sent after it
        handover.out = None
