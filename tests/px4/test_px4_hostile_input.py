"""Real PX4 v1.16 SITL towards a stranger, the reference the sim's endpoint follows: PX4 sets
its partner's address once (mavlink_receiver.cpp) and never sends to a newcomer, whatever
it sends; and SkyHelm's listening link keeps talking to PX4 through a flood of hostile
frames into its own port. Opt-in: `make test-px4` (SKYHELM_PX4_INSTANCE picks the instance).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import Any, cast

import pytest
from pymavlink.dialects.v20 import development as mavlink

from bench.hostile_input import SERVER_OUTCOME, HostileFrames
from server.link import Link, Vehicle
from tests.px4.conftest import Px4Sitl
from tests.waiting import holds_for, wait_for

pytestmark = pytest.mark.px4
LOOPBACK = "127.0.0.1"
# hostile datagrams into each end
FLOOD = 600


class _Stranger(asyncio.DatagramProtocol):
    def __init__(self) -> None:
        self.datagrams = 0
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.datagrams += 1


@pytest.fixture
async def stranger() -> AsyncIterator[_Stranger]:
    _, proto = await asyncio.get_running_loop().create_datagram_endpoint(
        _Stranger, local_addr=(LOOPBACK, 0))
    yield proto
    assert proto.transport is not None
    proto.transport.close()


async def _send_paced(stranger: _Stranger, frames: list[bytes], port: int) -> None:
    assert stranger.transport is not None
    for start in range(0, len(frames), 20):
        for frame in frames[start:start + 20]:
            stranger.transport.sendto(frame, (LOOPBACK, port))
        await asyncio.sleep(0.01)


async def test_px4_keeps_its_partner_and_skyhelm_its_vehicle_through_a_stranger(
    px4: Px4Sitl, stranger: _Stranger,
) -> None:
    async with await Link.open(px4.connect_url) as link:
        await wait_for(lambda: px4.sysid in link.vehicles, 60.0, "PX4 discovered")
        vehicle = link.vehicles[px4.sysid]
        assert isinstance(vehicle, Vehicle)
        px4_port = _px4_address(link, px4.sysid)[1]
        # into PX4's port: garbage, unverifiable ids, and a checked GCS HEARTBEAT
        to_px4 = HostileFrames(3, to_server=False, vehicle_sysid=px4.sysid)
        frames = [data for _, data in to_px4.datagrams(FLOOD)]
        heartbeat = mavlink.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
        frames.append(bytes(heartbeat.pack(mavlink.MAVLink(None, srcSystem=77,
                                                           srcComponent=190))))
        # into SkyHelm's port: the same kinds, claiming PX4's system id
        to_link = HostileFrames(4, to_server=True, vehicle_sysid=px4.sysid)
        link_port = px4.api_port
        frames_in = link.stats().frames_in
        await _send_paced(stranger, frames, px4_port)
        before = link.stats()
        expected = [0, 0]
        assert stranger.transport is not None
        for kind, data in to_link.datagrams(FLOOD):
            bad, unverified, _ = SERVER_OUTCOME[kind]
            expected[0] += bad
            expected[1] += unverified
            stranger.transport.sendto(data, (LOOPBACK, link_port))
            if sum(expected) % 10 == 0:  # a few in flight: the kernel drops none
                await wait_for(lambda: _counted(link, before) == tuple(expected), 10.0,
                               "the link counting the stranger's frames")
        await wait_for(lambda: _counted(link, before) == tuple(expected), 10.0,
                       "the link counting the stranger's frames")
        await holds_for(lambda: stranger.datagrams == 0, 2.0, "nothing from PX4 to a stranger")
        assert link.stats().frames_in > frames_in
        assert vehicle.snapshot().connected
        assert _px4_address(link, px4.sysid)[1] == px4_port
        # the link still talks to PX4: a command answered
        result = await vehicle.command_long(
            mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        assert result.ok, result


def _counted(link: Link, before: Any) -> tuple[int, int]:
    now = link.stats()
    return now.bad_frames - before.bad_frames, now.unverified_frames - before.unverified_frames


def _px4_address(link: Link, sysid: int) -> tuple[str, int]:
    """The address PX4's frames come from, as the listening link routes to it."""
    transport: Any = link._transport
    peer = transport._router.peer_of(sysid)
    assert peer is not None
    return cast(tuple[str, int], peer)
