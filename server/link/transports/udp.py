"""UDP transports: ``udpin:`` listens and answers whoever spoke, ``udpout:`` talks to one
address. Each datagram is decoded on its own: a frame never continues in the next one, so a
truncated frame at a datagram's end is counted and dropped instead of corrupting what follows."""

from __future__ import annotations

import asyncio
import logging
from typing import Any, cast

from pymavlink.dialects.v20 import development as mavlink

from ..urls import LinkUrl
from .base import FrameDecoder, FrameSink, Peer, PeerRouter, Transport, deliver, host_port

log = logging.getLogger(__name__)

# Broadcast frames (HEARTBEAT, untargeted) go to every UDP peer heard from this recently.
UDP_PEER_EXPIRY_S = 10.0


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

    def datagram_received(self, data: bytes, addr: tuple[str | Any, int]) -> None:
        if self._sink is not None:
            deliver(self._sink, self._decoder, data, addr, datagram=True,
                    before_each=self._frame_heard)

    def _frame_heard(self, msg: mavlink.MAVLink_message, peer: Peer) -> None:
        """Called for each good frame before the sink sees it."""

    async def close(self) -> None:
        if self._endpoint is not None:
            self._endpoint.close()
            self._endpoint = None


class UdpInTransport(_UdpTransport):
    """``udpin:``: listen; answer the peers that have sent us frames."""

    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        self._router = PeerRouter(expiry_s=UDP_PEER_EXPIRY_S)

    async def start(self, sink: FrameSink) -> None:
        await self._open_endpoint(sink, local_addr=(self.address.host, self.address.port))

    def write(self, frame: bytes, target_system: int | None) -> bool:
        if self._endpoint is None:
            return False
        destinations = self._router.destinations(target_system)
        for addr in destinations:
            self._endpoint.sendto(frame, cast(tuple[str, int], addr))
        return bool(destinations)

    def _frame_heard(self, msg: mavlink.MAVLink_message, peer: Peer) -> None:
        # A new peer's first frame reports a connection, so the link can introduce itself
        # (a GCS HEARTBEAT) at once instead of at its next 1 Hz tick.
        if self._router.heard(peer, msg.get_srcSystem()) and self._sink is not None:
            self._sink.connection_changed(True)


class UdpOutTransport(_UdpTransport):
    """``udpout:``: send to one fixed address; its answers come back on our socket."""

    async def start(self, sink: FrameSink) -> None:
        await self._open_endpoint(sink, remote_addr=(self.address.host, self.address.port))

    def write(self, frame: bytes, target_system: int | None) -> bool:
        if self._endpoint is None:
            return False
        self._endpoint.sendto(frame)
        return True
