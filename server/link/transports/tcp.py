"""TCP transports: ``tcp:`` connects (and reconnects), ``tcpin:`` serves any number of
clients. A connection is a byte stream with its own decoder; a client that stops reading
makes us drop frames rather than buffer without bound."""

from __future__ import annotations

import asyncio
import contextlib
import logging

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.aio import cancel_and_wait
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

MAX_STREAM_BACKLOG_BYTES = 256 * 1024
_READ_CHUNK_BYTES = 65536
_CLOSE_TIMEOUT_S = 1.0


def _write_stream(writer: asyncio.StreamWriter, frame: bytes) -> bool:
    if writer.is_closing() or writer.transport.get_write_buffer_size() > MAX_STREAM_BACKLOG_BYTES:
        return False
    writer.write(frame)
    return True


async def _pump_stream(
    reader: asyncio.StreamReader,
    writer: asyncio.StreamWriter,
    sink: FrameSink,
    peer: Peer,
    decoder: FrameDecoder,
    router: PeerRouter | None = None,
) -> None:
    """Deliver what the connection carries until it ends, then close it."""

    def heard(msg: mavlink.MAVLink_message, peer: Peer) -> None:
        if router is not None:
            router.heard(peer, msg.get_srcSystem())

    try:
        with contextlib.suppress(OSError):
            while data := await reader.read(_READ_CHUNK_BYTES):
                deliver(sink, decoder, data, peer, datagram=False, before_each=heard)
    finally:
        writer.close()
        with contextlib.suppress(OSError, asyncio.TimeoutError):
            await asyncio.wait_for(writer.wait_closed(), timeout=_CLOSE_TIMEOUT_S)


class TcpClientTransport(Transport):
    """``tcp:``: connect, and reconnect with exponential backoff whenever the peer goes away."""

    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        self._writer: asyncio.StreamWriter | None = None
        self._runner: asyncio.Task[None] | None = None

    @property
    def local_address(self) -> tuple[str, int] | None:
        if self._writer is None:
            return None
        return host_port(self._writer.get_extra_info("sockname"))

    async def start(self, sink: FrameSink) -> None:
        self._sink = sink
        self._runner = asyncio.get_running_loop().create_task(
            self._stay_connected(sink), name=f"tcp:{self.address.url}"
        )

    def write(self, frame: bytes, target_system: int | None) -> bool:
        return self._writer is not None and _write_stream(self._writer, frame)

    async def close(self) -> None:
        await cancel_and_wait(self._runner)
        self._runner = None

    async def _stay_connected(self, sink: FrameSink) -> None:
        while True:
            try:
                reader, writer = await asyncio.open_connection(self.address.host, self.address.port)
            except OSError as exc:
                log.debug("%s: connect failed (%s); retry in %.1f s", self.address.url, exc,
                          self.backoff_s)
                await asyncio.sleep(self.backoff_s)
                self._waited_in_vain()
                continue
            self._opened()
            self._writer = writer
            sink.connection_changed(True)
            try:
                await _pump_stream(reader, writer, sink, None, self._new_decoder())
            finally:
                self._writer = None
            sink.connection_changed(False)
            log.info("%s: connection closed; reconnecting", self.address.url)
            await asyncio.sleep(self.backoff_s)


class TcpServerTransport(Transport):
    """``tcpin:``: serve any number of TCP clients; frames for a system go to its client."""

    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        self._server: asyncio.Server | None = None
        self._clients: dict[Peer, asyncio.StreamWriter] = {}
        self._router = PeerRouter(expiry_s=None)

    @property
    def local_address(self) -> tuple[str, int] | None:
        if self._server is None or not self._server.sockets:
            return None
        return host_port(self._server.sockets[0].getsockname())

    async def start(self, sink: FrameSink) -> None:
        self._sink = sink
        self._server = await asyncio.start_server(
            self._serve_client, self.address.host, self.address.port
        )

    def write(self, frame: bytes, target_system: int | None) -> bool:
        peer = self._router.peer_of(target_system)
        destinations = [peer] if peer in self._clients else list(self._clients)
        written = [_write_stream(self._clients[p], frame) for p in destinations]
        return any(written)

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            for writer in list(self._clients.values()):
                writer.close()
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._server.wait_closed(), timeout=_CLOSE_TIMEOUT_S)
            self._server = None

    async def _serve_client(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        peer: Peer = writer.get_extra_info("peername")
        self._clients[peer] = writer
        assert self._sink is not None
        self._sink.connection_changed(True)
        try:
            await _pump_stream(
                reader, writer, self._sink, peer, self._new_decoder(), self._router
            )
        finally:
            self._clients.pop(peer, None)
            self._router.forget(peer)
            self._sink.connection_changed(False)
