import asyncio
import contextlib
import os
import socket
from collections.abc import AsyncIterator
from typing import Any

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.urls import parse_link_url
from server.link.transports import (
    FrameDecoder,
    Peer,
    SerialTransport,
    TcpClientTransport,
    TcpServerTransport,
    Transport,
    UdpInTransport,
    UdpOutTransport,
)
from tests.waiting import wait_for as _until


def _frame(src_system: int, seq: int = 0, *, mavlink1: bool = False) -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=src_system, srcComponent=1)
    mav.seq = seq
    msg = mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0)
    return bytes(msg.pack(mav, force_mavlink1=mavlink1))


class _Sink:
    def __init__(self) -> None:
        self.frames: list[tuple[mavlink.MAVLink_message, Peer]] = []
        self.bad = 0
        self.bytes = 0
        self.connection_events: list[bool] = []

    def frame_received(self, msg: mavlink.MAVLink_message, peer: Peer) -> None:
        self.frames.append((msg, peer))

    def bad_frames_received(self, count: int) -> None:
        self.bad += count

    def bytes_received(self, count: int) -> None:
        self.bytes += count

    def connection_changed(self, connected: bool) -> None:
        self.connection_events.append(connected)

    def systems(self) -> list[int]:
        return [m.get_srcSystem() for m, _ in self.frames]


class _UdpPeer(asyncio.DatagramProtocol):
    """A bare UDP socket on 127.0.0.1 standing in for a vehicle or router."""

    def __init__(self) -> None:
        self.received: list[bytes] = []
        self.endpoint: asyncio.DatagramTransport | None = None

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.received.append(data)

    @property
    def port(self) -> int:
        assert self.endpoint is not None
        return int(self.endpoint.get_extra_info("sockname")[1])

    def send(self, data: bytes, port: int) -> None:
        assert self.endpoint is not None
        self.endpoint.sendto(data, ("127.0.0.1", port))


@contextlib.asynccontextmanager
async def _udp_peer() -> AsyncIterator[_UdpPeer]:
    peer = _UdpPeer()
    loop = asyncio.get_running_loop()
    peer.endpoint, _ = await loop.create_datagram_endpoint(lambda: peer,
                                                           local_addr=("127.0.0.1", 0))
    try:
        yield peer
    finally:
        peer.endpoint.close()


@contextlib.asynccontextmanager
async def _started(transport: Transport) -> AsyncIterator[_Sink]:
    sink = _Sink()
    await transport.start(sink)
    try:
        yield sink
    finally:
        await transport.close()


def _port(transport: Transport) -> int:
    assert transport.local_address is not None
    return transport.local_address[1]


async def test_udpin_drops_writes_until_a_peer_speaks_then_answers_it() -> None:
    transport = UdpInTransport(parse_link_url("udpin:127.0.0.1:0"))
    async with _started(transport) as sink, _udp_peer() as peer:
        assert transport.write(b"x", None) is False
        peer.send(_frame(1), _port(transport))
        await _until(lambda: sink.systems() == [1])
        assert transport.write(_frame(255), None) is True
        await _until(lambda: peer.received == [_frame(255)])


async def test_udpin_sends_targeted_frames_only_to_that_systems_peer() -> None:
    transport = UdpInTransport(parse_link_url("udpin:127.0.0.1:0"))
    async with _started(transport) as sink, _udp_peer() as one, _udp_peer() as two:
        one.send(_frame(1), _port(transport))
        two.send(_frame(2), _port(transport))
        await _until(lambda: sorted(sink.systems()) == [1, 2])
        transport.write(b"for-two", 2)
        transport.write(b"for-all", None)
        await _until(lambda: len(two.received) == 2 and len(one.received) == 1)
        assert one.received == [b"for-all"]
        assert two.received == [b"for-two", b"for-all"]


async def test_udpout_sends_to_its_address_and_hears_the_answers() -> None:
    async with _udp_peer() as peer:
        transport = UdpOutTransport(parse_link_url(f"udpout:127.0.0.1:{peer.port}"))
        async with _started(transport) as sink:
            assert transport.write(_frame(255), None) is True
            await _until(lambda: peer.received == [_frame(255)])
            peer.send(_frame(1), _port(transport))
            await _until(lambda: sink.systems() == [1])


async def test_garbage_truncated_and_bad_crc_datagrams_are_counted_and_dropped() -> None:
    bad_crc = bytearray(_frame(1, 1))
    bad_crc[-3] ^= 0xFF  # a payload byte, so the checksum no longer matches
    transport = UdpInTransport(parse_link_url("udpin:127.0.0.1:0"))
    async with _started(transport) as sink, _udp_peer() as peer:
        datagrams = [
            b"\x00garbage that is not mavlink",
            _frame(1, 0)[:9],
            bytes(bad_crc),
            _frame(1, 2, mavlink1=True),
            _frame(1, 3) + _frame(1, 4)[:12],  # good frame, then a truncated one
            _frame(1, 5),
        ]
        for data in datagrams:
            peer.send(data, _port(transport))
        await _until(lambda: len(sink.frames) == 3)
        await _until(lambda: sink.bytes == sum(map(len, datagrams)))
        assert [m.get_seq() for m, _ in sink.frames] == [2, 3, 5]
        assert sink.bad == 4


def test_frame_fed_byte_by_byte_decodes_once() -> None:
    decoder = FrameDecoder()
    frame = _frame(3, 9)
    results = [decoder.feed(frame[i : i + 1]) for i in range(len(frame))]
    frames = [m for good, _ in results for m in good]
    assert [(m.get_srcSystem(), m.get_seq()) for m in frames] == [(3, 9)]
    assert sum(bad for _, bad in results) == 0


class _TcpServer:
    """A TCP peer that can be stopped and started again on the same port."""

    def __init__(self) -> None:
        self.port = 0
        self.received = bytearray()
        self.clients: list[asyncio.StreamWriter] = []
        self._server: asyncio.Server | None = None

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._serve, "127.0.0.1", self.port)
        self.port = self._server.sockets[0].getsockname()[1]

    async def stop(self) -> None:
        assert self._server is not None
        self._server.close()
        for writer in self.clients:
            writer.close()
        self.clients.clear()
        await self._server.wait_closed()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.clients.append(writer)
        while data := await reader.read(4096):
            self.received += data

    def broadcast(self, data: bytes) -> None:
        for writer in self.clients:
            writer.write(data)


async def test_tcp_client_reconnects_after_the_server_restarts() -> None:
    server = _TcpServer()
    await server.start()
    transport = TcpClientTransport(parse_link_url(f"tcp:127.0.0.1:{server.port}"))
    async with _started(transport) as sink:
        await _until(lambda: len(server.clients) == 1)
        server.broadcast(_frame(1, 0))
        await _until(lambda: sink.systems() == [1])

        await server.stop()
        await _until(lambda: sink.connection_events == [True, False])
        assert transport.write(_frame(255), None) is False
        await server.start()
        await _until(lambda: len(server.clients) == 1)
        await _until(lambda: sink.connection_events == [True, False, True])
        server.broadcast(_frame(1, 1))
        await _until(lambda: len(sink.frames) == 2)
        assert transport.write(_frame(255), None) is True
        await _until(lambda: bytes(server.received) == _frame(255))
        assert transport.reconnects == 1
    await server.stop()


async def test_tcp_client_backs_off_exponentially_while_nobody_listens() -> None:
    server = _TcpServer()
    await server.start()
    await server.stop()  # a port that was just free: connecting is refused
    transport = TcpClientTransport(parse_link_url(f"tcp:127.0.0.1:{server.port}"))
    async with _started(transport) as sink:
        assert transport.backoff_s == 0.5
        await _until(lambda: transport.backoff_s == 2.0, timeout_s=4.0)
        assert sink.connection_events == []


async def test_tcpin_serves_several_clients_and_routes_by_system() -> None:
    transport = TcpServerTransport(parse_link_url("tcpin:127.0.0.1:0"))
    async with _started(transport) as sink:
        clients = [await asyncio.open_connection("127.0.0.1", _port(transport)) for _ in "ab"]
        for sysid, (_, writer) in enumerate(clients, start=1):
            writer.write(_frame(sysid))
        await _until(lambda: sorted(sink.systems()) == [1, 2])
        assert transport.write(b"to-2", 2)
        assert transport.write(b"to-all", None)
        first = await asyncio.wait_for(clients[0][0].readexactly(6), 5.0)
        second = await asyncio.wait_for(clients[1][0].readexactly(10), 5.0)
        assert (first, second) == (b"to-all", b"to-2to-all")
        for _, writer in clients:
            writer.close()
        await _until(lambda: sink.connection_events.count(False) == 2)


async def test_serial_port_carries_frames_both_ways_and_reports_the_device_lost() -> None:
    pytest.importorskip("serial")
    controller_fd, device_fd = os.openpty()
    os.set_blocking(controller_fd, False)
    transport = SerialTransport(parse_link_url(f"{os.ttyname(device_fd)}:57600"))
    try:
        async with _started(transport) as sink:
            await _until(lambda: sink.connection_events == [True])
            frame = _frame(1, 4)
            os.write(controller_fd, frame[:7])
            os.write(controller_fd, frame[7:])
            await _until(lambda: sink.systems() == [1])
            assert transport.write(_frame(255), None)
            received = bytearray()

            def read_available() -> bool:
                with contextlib.suppress(BlockingIOError):
                    received.extend(os.read(controller_fd, 1024))
                return bytes(received) == _frame(255)

            await _until(read_available)
            os.close(controller_fd)  # the cable is pulled
            controller_fd = -1
            await _until(lambda: sink.connection_events == [True, False])
            assert transport.write(_frame(255), None) is False
    finally:
        if controller_fd >= 0:
            os.close(controller_fd)
        os.close(device_fd)


async def test_a_udp_link_reads_a_backlog_in_a_few_turns_of_the_loop() -> None:
    """A loop busy with many links must not read one datagram per wakeup: 200 frames queued
    while the loop was held up are all read within a few turns of it."""
    transport = UdpInTransport(parse_link_url("udpin:127.0.0.1:0"))
    sink = _Sink()
    await transport.start(sink)
    assert transport.local_address is not None
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for seq in range(200):
            sender.sendto(_frame(7, seq % 256), transport.local_address)
        assert transport.input_pending()
        turns = 0
        while len(sink.frames) < 200 and turns < 100:
            await asyncio.sleep(0)
            turns += 1
        assert len(sink.frames) == 200
        assert turns <= 20, f"{turns} turns of the loop to read 200 queued datagrams"
        assert not transport.input_pending()
    finally:
        sender.close()
        await transport.close()
