"""Byte transports for a link, each turning bytes into decoded MAVLink frames on the event loop.

UDP and TCP use asyncio datagram endpoints and streams; a serial port is read by one thread
that hands its bytes to the loop. Decoding (pymavlink, ``development`` dialect, MAVLink 1
and 2) happens on the loop, with one decoder per byte stream: a TCP connection, a serial
port, or a single UDP datagram (a datagram never continues in the next one, so a truncated
frame at its end is counted and dropped instead of corrupting what follows).

Writes never block: a transport that cannot take a frame now (no peer yet, not connected,
a full socket backlog) drops it and says so by returning False.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Hashable
from typing import Any, Protocol, cast

from pymavlink.dialects.v20 import development as mavlink

from .urls import LinkUrl

log = logging.getLogger(__name__)

Peer = Hashable  # a UDP (host, port) address, a TCP client, or None for point-to-point links

# A TCP client that stops reading must not make us buffer without bound.
MAX_STREAM_BACKLOG_BYTES = 256 * 1024
RECONNECT_BACKOFF_MIN_S = 0.5
RECONNECT_BACKOFF_MAX_S = 5.0
# Broadcast frames (HEARTBEAT, untargeted) go to every UDP peer heard from this recently.
UDP_PEER_EXPIRY_S = 10.0
# Peers remembered per listening link; beyond this the longest silent one is forgotten.
MAX_PEERS = 64
_READ_CHUNK_BYTES = 65536
_SERIAL_READ_TIMEOUT_S = 0.05


class FrameSink(Protocol):
    """What a transport reports to its link; every call happens on the event loop."""

    def frame_received(self, msg: mavlink.MAVLink_message, peer: Peer) -> None: ...

    def bad_frames_received(self, count: int) -> None: ...

    def bytes_received(self, count: int) -> None: ...

    def connection_changed(self, connected: bool) -> None: ...


class FrameDecoder:
    """pymavlink's parser in robust mode: garbage, bad CRC and truncation become counts."""

    def __init__(self) -> None:
        self._mav = mavlink.MAVLink(None)
        self._mav.robust_parsing = True

    def feed(self, data: bytes) -> tuple[list[mavlink.MAVLink_message], int]:
        """Decode what ``data`` completes; return (good frames, bad frame count)."""
        parsed = self._mav.parse_buffer(data) or []
        good = [m for m in parsed if not isinstance(m, mavlink.MAVLink_bad_data)]
        return good, len(parsed) - len(good)

    def discard_partial(self) -> bool:
        """Forget a frame still incomplete; True when there was one (it was truncated)."""
        if self._mav.buf_len() == 0:
            return False
        self._mav.buf = bytearray()
        self._mav.buf_index = 0
        self._mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        return True


def deliver(
    sink: FrameSink, decoder: FrameDecoder, data: bytes, peer: Peer, *, datagram: bool
) -> None:
    sink.bytes_received(len(data))
    frames, bad = decoder.feed(data)
    if datagram and decoder.discard_partial():
        bad += 1
    if bad:
        sink.bad_frames_received(bad)
    for msg in frames:
        sink.frame_received(msg, peer)


class _PeerRouter:
    """Sends a frame for system S to the peer S was last heard from; others to every peer."""

    def __init__(self, expiry_s: float | None) -> None:
        self._expiry_s = expiry_s
        self._peer_by_system: dict[int, Peer] = {}
        self._last_heard: dict[Peer, float] = {}

    def heard(self, peer: Peer, src_system: int) -> bool:
        """Note a frame from ``peer``; True when the peer was not known before."""
        self._peer_by_system[src_system] = peer
        is_new = self._last_heard.pop(peer, None) is None  # re-insert: order is recency
        self._last_heard[peer] = time.monotonic()
        if len(self._last_heard) > MAX_PEERS:
            self.forget(next(iter(self._last_heard)))
        return is_new

    def forget(self, peer: Peer) -> None:
        self._last_heard.pop(peer, None)
        for system in [s for s, p in self._peer_by_system.items() if p == peer]:
            del self._peer_by_system[system]

    def peer_of(self, target_system: int | None) -> Peer | None:
        """The peer a targeted frame should go to; None for broadcasts and unknown systems."""
        if not target_system:
            return None
        peer = self._peer_by_system.get(target_system)
        return peer if peer in self._last_heard else None

    def destinations(self, target_system: int | None) -> list[Peer]:
        peer = self.peer_of(target_system)
        if peer is not None:
            return [peer]
        if not self._last_heard:
            return []
        if self._expiry_s is None:
            return list(self._last_heard)
        oldest_allowed = time.monotonic() - self._expiry_s
        recent = [p for p, t in self._last_heard.items() if t >= oldest_allowed]
        # Nobody recent: still answer the last one who spoke, as pymavlink's udpin does.
        return recent or [next(reversed(self._last_heard))]


class Transport(ABC):
    """One connection of a link. ``start`` binds or connects; ``write`` never blocks."""

    def __init__(self, address: LinkUrl) -> None:
        self.address = address
        self.reconnects = 0
        self._sink: FrameSink | None = None

    @property
    def local_address(self) -> tuple[str, int] | None:
        """The bound (host, port), e.g. to learn an ephemeral port; None for serial."""
        return None

    @abstractmethod
    async def start(self, sink: FrameSink) -> None: ...

    @abstractmethod
    def write(self, frame: bytes, target_system: int | None) -> bool: ...

    @abstractmethod
    async def close(self) -> None: ...


def create_transport(address: LinkUrl) -> Transport:
    from .replay import ReplayTransport  # it builds on this module's classes

    transports: dict[str, type[Transport]] = {
        "udpin": UdpInTransport,
        "udpout": UdpOutTransport,
        "tcp": TcpClientTransport,
        "tcpin": TcpServerTransport,
        "serial": SerialTransport,
        "tlog": ReplayTransport,
    }
    return transports[address.kind](address)


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
        host, port = self._endpoint.get_extra_info("sockname")[:2]
        return str(host), int(port)

    async def _open_endpoint(self, **kwargs: Any) -> None:
        loop = asyncio.get_running_loop()
        endpoint, _ = await loop.create_datagram_endpoint(
            lambda: _DatagramReceiver(self), **kwargs
        )
        self._endpoint = endpoint

    def datagram_received(self, data: bytes, addr: tuple[str | Any, int]) -> None:
        if self._sink is not None:
            deliver(self._sink, self._decoder, data, addr, datagram=True)

    async def close(self) -> None:
        if self._endpoint is not None:
            self._endpoint.close()
            self._endpoint = None


class UdpInTransport(_UdpTransport):
    """``udpin:``: listen; answer the peers that have sent us frames."""

    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        self._router = _PeerRouter(expiry_s=UDP_PEER_EXPIRY_S)

    async def start(self, sink: FrameSink) -> None:
        self._sink = _RoutingSink(sink, self._router, announce_new_peers=True)
        await self._open_endpoint(local_addr=(self.address.host, self.address.port))

    def write(self, frame: bytes, target_system: int | None) -> bool:
        if self._endpoint is None:
            return False
        destinations = self._router.destinations(target_system)
        for addr in destinations:
            self._endpoint.sendto(frame, cast(tuple[str, int], addr))
        return bool(destinations)


class UdpOutTransport(_UdpTransport):
    """``udpout:``: send to one fixed address; its answers come back on our socket."""

    async def start(self, sink: FrameSink) -> None:
        self._sink = sink
        await self._open_endpoint(remote_addr=(self.address.host, self.address.port))

    def write(self, frame: bytes, target_system: int | None) -> bool:
        if self._endpoint is None:
            return False
        self._endpoint.sendto(frame)
        return True


class _RoutingSink:
    """Passes frames on while noting which peer each system speaks from.

    With ``announce_new_peers`` a UDP peer's first frame reports a connection, so the link
    can introduce itself (a GCS HEARTBEAT) at once instead of at its next 1 Hz tick.
    """

    def __init__(self, sink: FrameSink, router: _PeerRouter, *, announce_new_peers: bool) -> None:
        self._sink = sink
        self._router = router
        self._announce_new_peers = announce_new_peers

    def frame_received(self, msg: mavlink.MAVLink_message, peer: Peer) -> None:
        is_new = self._router.heard(peer, msg.get_srcSystem())
        if is_new and self._announce_new_peers:
            self._sink.connection_changed(True)
        self._sink.frame_received(msg, peer)

    def bad_frames_received(self, count: int) -> None:
        self._sink.bad_frames_received(count)

    def bytes_received(self, count: int) -> None:
        self._sink.bytes_received(count)

    def connection_changed(self, connected: bool) -> None:
        self._sink.connection_changed(connected)


def _write_stream(writer: asyncio.StreamWriter, frame: bytes) -> bool:
    if writer.is_closing() or writer.transport.get_write_buffer_size() > MAX_STREAM_BACKLOG_BYTES:
        return False
    writer.write(frame)
    return True


async def _pump_stream(
    reader: asyncio.StreamReader, sink: FrameSink, peer: Peer
) -> None:
    decoder = FrameDecoder()
    with contextlib.suppress(OSError):
        while data := await reader.read(_READ_CHUNK_BYTES):
            deliver(sink, decoder, data, peer, datagram=False)


async def _close_writer(writer: asyncio.StreamWriter) -> None:
    writer.close()
    with contextlib.suppress(OSError, asyncio.TimeoutError):
        await asyncio.wait_for(writer.wait_closed(), timeout=1.0)


class TcpClientTransport(Transport):
    """``tcp:``: connect, and reconnect with exponential backoff whenever the peer goes away."""

    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        self._writer: asyncio.StreamWriter | None = None
        self._runner: asyncio.Task[None] | None = None
        self.backoff_s = RECONNECT_BACKOFF_MIN_S

    @property
    def local_address(self) -> tuple[str, int] | None:
        if self._writer is None:
            return None
        host, port = self._writer.get_extra_info("sockname")[:2]
        return str(host), int(port)

    async def start(self, sink: FrameSink) -> None:
        self._sink = sink
        self._runner = asyncio.get_running_loop().create_task(
            self._stay_connected(sink), name=f"tcp:{self.address.url}"
        )

    def write(self, frame: bytes, target_system: int | None) -> bool:
        return self._writer is not None and _write_stream(self._writer, frame)

    async def close(self) -> None:
        if self._runner is not None:
            self._runner.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._runner
            self._runner = None

    async def _stay_connected(self, sink: FrameSink) -> None:
        ever_connected = False
        while True:
            try:
                reader, writer = await asyncio.open_connection(self.address.host, self.address.port)
            except OSError as exc:
                log.debug("%s: connect failed (%s); retry in %.1f s", self.address.url, exc,
                          self.backoff_s)
                await asyncio.sleep(self.backoff_s)
                self.backoff_s = min(self.backoff_s * 2, RECONNECT_BACKOFF_MAX_S)
                continue
            if ever_connected:
                self.reconnects += 1
            ever_connected = True
            self.backoff_s = RECONNECT_BACKOFF_MIN_S
            self._writer = writer
            sink.connection_changed(True)
            try:
                await _pump_stream(reader, sink, None)
            finally:
                self._writer = None
                await _close_writer(writer)
            sink.connection_changed(False)
            log.info("%s: connection closed; reconnecting", self.address.url)
            await asyncio.sleep(self.backoff_s)


class TcpServerTransport(Transport):
    """``tcpin:``: serve any number of TCP clients; frames for a system go to its client."""

    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        self._server: asyncio.Server | None = None
        self._clients: dict[Peer, asyncio.StreamWriter] = {}
        self._router = _PeerRouter(expiry_s=None)

    @property
    def local_address(self) -> tuple[str, int] | None:
        if self._server is None or not self._server.sockets:
            return None
        host, port = self._server.sockets[0].getsockname()[:2]
        return str(host), int(port)

    async def start(self, sink: FrameSink) -> None:
        self._sink = _RoutingSink(sink, self._router, announce_new_peers=False)
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
                await asyncio.wait_for(self._server.wait_closed(), timeout=1.0)
            self._server = None

    async def _serve_client(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        peer: Peer = writer.get_extra_info("peername")
        self._clients[peer] = writer
        assert self._sink is not None
        self._sink.connection_changed(True)
        try:
            await _pump_stream(reader, self._sink, peer)
        finally:
            self._clients.pop(peer, None)
            self._router.forget(peer)
            await _close_writer(writer)
            self._sink.connection_changed(False)


class SerialTransport(Transport):
    """A serial port read by one thread; reopened with backoff when the device goes away."""

    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        self._serial: Any = None  # serial.Serial while open
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._decoder = FrameDecoder()

    async def start(self, sink: FrameSink) -> None:
        self._sink = sink
        loop = asyncio.get_running_loop()
        self._thread = threading.Thread(
            target=self._read_forever, args=(loop, sink), name=f"serial:{self.address.device}",
            daemon=True,
        )
        self._thread.start()

    def write(self, frame: bytes, target_system: int | None) -> bool:
        import serial

        port = self._serial
        if port is None:
            return False
        try:
            # write_timeout=0 makes this non-blocking: a full driver buffer raises instead.
            return bool(port.write(frame) == len(frame))
        except (serial.SerialException, OSError):
            return False

    async def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, 2.0)
            self._thread = None

    def _read_forever(self, loop: asyncio.AbstractEventLoop, sink: FrameSink) -> None:
        import serial

        backoff_s = RECONNECT_BACKOFF_MIN_S
        ever_opened = False
        while not self._stop.is_set():
            try:
                port = serial.Serial(
                    self.address.device, self.address.baud,
                    timeout=_SERIAL_READ_TIMEOUT_S, write_timeout=0,
                )
            except (serial.SerialException, OSError) as exc:
                log.debug("%s: open failed (%s)", self.address.url, exc)
                self._stop.wait(backoff_s)
                backoff_s = min(backoff_s * 2, RECONNECT_BACKOFF_MAX_S)
                continue
            if ever_opened:
                self.reconnects += 1
            ever_opened = True
            backoff_s = RECONNECT_BACKOFF_MIN_S
            self._serial = port
            loop.call_soon_threadsafe(sink.connection_changed, True)
            try:
                while not self._stop.is_set():
                    data = port.read(max(1, port.in_waiting))
                    if data:
                        loop.call_soon_threadsafe(self._deliver, sink, bytes(data))
            except (serial.SerialException, OSError, TypeError) as exc:
                log.info("%s: device lost (%s)", self.address.url, exc)
            except RuntimeError:  # the loop closed under us: nothing left to deliver to
                self._stop.set()
            finally:
                self._serial = None
                with contextlib.suppress(Exception):
                    port.close()
                with contextlib.suppress(RuntimeError):  # the loop may be gone at shutdown
                    loop.call_soon_threadsafe(sink.connection_changed, False)
            self._stop.wait(backoff_s)

    def _deliver(self, sink: FrameSink, data: bytes) -> None:
        # Runs on the loop, so the decoder is only ever touched there.
        deliver(sink, self._decoder, data, None, datagram=False)
