"""UDP transports: ``udpin:`` listens and answers whoever spoke, ``udpout:`` talks to one
address. Each datagram is decoded on its own: a frame never continues in the next one, so a
truncated frame at a datagram's end is counted and dropped instead of corrupting what follows.

Only frames whose checksum was checked tell ``udpin:`` who its peers are. pymavlink hands
frames of ids outside its dialect over as UNKNOWN_<id> without checking anything, and random
bytes often parse as one: such a frame never makes a sender a peer, nor moves a system to a
new address (the link counts and drops it). A checked frame that claims a system still
heard from another address (within ``UDP_PEER_HANDOVER_S``) is counted as bad and dropped:
the system's address moves only once the old one has gone quiet (a rebooted vehicle on a
new port). ``udpout:`` sockets are connected, so the OS delivers only its peer's datagrams."""

from __future__ import annotations

import asyncio
import fcntl
import logging
import os
import socket
import sys
import termios
from collections.abc import Callable
from typing import Any, cast

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.px4_messages import decode_unknown
from server.link.codec.urls import LinkUrl
from server.link.transports.base import (
    FrameDecoder,
    FrameSink,
    Peer,
    PeerRouter,
    Transport,
    deliver,
    host_port,
)

log = logging.getLogger(__name__)

# Broadcast frames (HEARTBEAT, untargeted) go to every UDP peer heard from this recently.
UDP_PEER_EXPIRY_S = 10.0
# A system heard from one address is not taken from another until the first is this quiet.
UDP_PEER_HANDOVER_S = 2.0
# Datagrams read per wakeup of a socket (the rest wait for the next turn of the loop).
DRAIN_PER_WAKEUP = 64
MAX_DATAGRAM_BYTES = 65535
# The receive buffer asked of the OS for a link socket (it grants up to net.core.rmem_max).
# Its default (212 KB) holds only ~256 datagrams however small: a vehicle sending PX4's
# ~200 frames/s to a server held off its core for a second or two (a busy laptop, a slow
# call in the loop) would lose frames, answers to commands among them. 4 MiB holds ~10,000
# (under a minute of PX4's stream), delivered late rather than lost.
LINK_RECEIVE_BUFFER_BYTES = 4 * 1024 * 1024


def _widen_receive_buffer(sock: socket.socket) -> None:
    """Ask for ``LINK_RECEIVE_BUFFER_BYTES`` on ``sock``; say so when the OS grants less (Linux
    reports twice what it holds for data, its own bookkeeping included)."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, LINK_RECEIVE_BUFFER_BYTES)
        granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    except OSError as exc:
        log.debug("receive buffer of %d bytes refused: %s", LINK_RECEIVE_BUFFER_BYTES, exc)
        return
    if granted < LINK_RECEIVE_BUFFER_BYTES:
        log.info("a link socket's receive buffer is %d bytes, not the %d asked "
                 "(net.core.rmem_max caps it)", granted, LINK_RECEIVE_BUFFER_BYTES)


class _DatagramReceiver(asyncio.DatagramProtocol):
    def __init__(self, owner: _UdpTransport) -> None:
        self._owner = owner

    def datagram_received(self, data: bytes, addr: tuple[str | Any, int]) -> None:
        self._owner.datagram_received(data, addr)

    def error_received(self, exc: Exception) -> None:
        # ICMP "port unreachable" while the peer is not up yet: normal, it will come.
        log.debug("%s: %s", self._owner.address.url, exc)


class _UdpTransport(Transport):
    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        self._endpoint: asyncio.DatagramTransport | None = None
        self._decoder = FrameDecoder()
        # a duplicate of the endpoint's socket for writes off the loop (asyncio's transport
        # is not thread-safe); it shares the non-blocking mode, so it never blocks either
        self._thread_socket: socket.socket | None = None

    @property
    def local_address(self) -> tuple[str, int] | None:
        if self._endpoint is None:
            return None
        return host_port(self._endpoint.get_extra_info("sockname"))

    async def _open_endpoint(self, sink: FrameSink, **kwargs: Any) -> None:
        self._sink = sink
        self._decoder = self._new_decoder()
        loop = asyncio.get_running_loop()
        endpoint, _ = await loop.create_datagram_endpoint(
            lambda: _DatagramReceiver(self), **kwargs
        )
        self._endpoint = endpoint
        sock = endpoint.get_extra_info("socket")
        _widen_receive_buffer(sock)
        self._thread_socket = socket.socket(
            sock.family, sock.type, sock.proto, fileno=os.dup(sock.fileno()))

    def thread_writer(self) -> Callable[[bytes, int | None], bool] | None:
        return self._write_off_loop

    def process_socket(self) -> socket.socket | None:
        return self._thread_socket

    def input_pending(self) -> bool:
        # FIONREAD on a datagram socket: the size of the next queued datagram, 0 if none
        sock = self._thread_socket
        if sock is None:
            return False
        try:
            size = fcntl.ioctl(sock.fileno(), termios.FIONREAD, b"\0\0\0\0")
        except OSError:
            return False
        return int.from_bytes(size, sys.byteorder) > 0

    def _write_off_loop(self, frame: bytes, target_system: int | None) -> bool:
        sock = self._thread_socket
        if sock is None:
            return False
        try:
            return self._send_off_loop(sock, frame, target_system)
        except OSError:  # buffer full (non-blocking), or closed under us: dropped, counted
            return False

    def _send_off_loop(self, sock: socket.socket, frame: bytes, target_system: int | None
                       ) -> bool:
        raise NotImplementedError

    def datagram_received(self, data: bytes, addr: tuple[str | Any, int]) -> None:
        self._deliver_datagram(data, addr)
        # asyncio reads one datagram per wakeup of the socket: a busy loop serving many
        # links would read each slower than its vehicle sends (PX4: ~100 frames/s) and fall
        # seconds behind. Read what else is queued now, up to a bound per wakeup.
        sock = self._thread_socket
        for _ in range(DRAIN_PER_WAKEUP - 1):
            if sock is None or self._sink is None:
                return
            try:
                data, addr = sock.recvfrom(MAX_DATAGRAM_BYTES)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # ICMP errors surface here too; the next read goes on
                log.debug("%s: %s", self.address.url, exc)
                return
            self._deliver_datagram(data, addr)

    def _deliver_datagram(self, data: bytes, addr: tuple[str | Any, int]) -> None:
        if self._sink is None:
            return
        try:
            deliver(self._sink, self._decoder, data, addr, datagram=True,
                    before_each=self._frame_heard)
        except Exception:
            # pymavlink raises on inputs its robust mode misses: one bad datagram, counted
            log.debug("%s: undecodable datagram", self.address.url, exc_info=True)
            self._decoder.discard_partial()
            self._sink.bad_frames_received(1)

    def _frame_heard(self, msg: mavlink.MAVLink_message, peer: Peer) -> bool | None:
        """Called for each good frame before the sink sees it; False drops it."""
        return None

    async def close(self) -> None:
        if self._thread_socket is not None:
            self._thread_socket.close()
            self._thread_socket = None
        if self._endpoint is not None:
            self._endpoint.close()
            self._endpoint = None


class UdpInTransport(_UdpTransport):
    """``udpin:``: listen; answer the peers that have sent us frames."""

    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        self._router = PeerRouter(expiry_s=UDP_PEER_EXPIRY_S)
        # checked frames dropped: their system is heard from another address
        self.foreign_frames = 0

    async def start(self, sink: FrameSink) -> None:
        await self._open_endpoint(sink, local_addr=(self.address.host, self.address.port))

    def write(self, frame: bytes, target_system: int | None) -> bool:
        if self._endpoint is None:
            return False
        destinations = self._router.destinations(target_system)
        for addr in destinations:
            self._endpoint.sendto(frame, cast(tuple[str, int], addr))
        return bool(destinations)

    def destinations_of(self, target_system: int | None) -> list[Any] | None:
        return list(self._router.destinations(target_system))

    def _send_off_loop(self, sock: socket.socket, frame: bytes, target_system: int | None
                       ) -> bool:
        peer = self._router.peer_of(target_system)
        destinations = [peer] if peer is not None else self._router.every_peer()
        for addr in destinations:
            sock.sendto(frame, cast(tuple[str, int], addr))
        return bool(destinations)

    def _frame_heard(self, msg: mavlink.MAVLink_message, peer: Peer) -> bool | None:
        if isinstance(msg, mavlink.MAVLink_unknown):
            decoded = decode_unknown(msg)
            if decoded is None:
                return None  # unchecked: the link counts and drops it, it names no peer
            msg = decoded  # pymavlink leaves an UNKNOWN_<id>'s header ids unset
        src_system = msg.get_srcSystem()
        owner = self._router.peer_of(src_system)
        if (owner is not None and owner != peer
                and self._router.silent_s(owner) < UDP_PEER_HANDOVER_S):
            self.foreign_frames += 1
            if self._sink is not None:
                self._sink.bad_frames_received(1)
            return False
        # A new peer's first frame reports a connection, so the link can introduce itself
        # (a GCS HEARTBEAT) at once instead of at its next 1 Hz tick.
        if self._router.heard(peer, src_system) and self._sink is not None:
            self._sink.connection_changed(True)
        return None


class UdpOutTransport(_UdpTransport):
    """``udpout:``: send to one fixed address; its answers come back on our socket."""

    async def start(self, sink: FrameSink) -> None:
        await self._open_endpoint(sink, remote_addr=(self.address.host, self.address.port))

    def write(self, frame: bytes, target_system: int | None) -> bool:
        if self._endpoint is None:
            return False
        self._endpoint.sendto(frame)
        return True

    def _send_off_loop(self, sock: socket.socket, frame: bytes, target_system: int | None
                       ) -> bool:
        sock.send(frame)  # connected to the one peer
        return True
