"""What every transport shares: the sink it reports to, frame decoding, the reconnect backoff
and the routing of frames to the peers that spoke from each system."""

from __future__ import annotations

import socket
from abc import ABC, abstractmethod
from collections.abc import Callable, Hashable
from typing import Any, Protocol

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.aio import loop_time_s
from server.link.codec.urls import LinkUrl

Peer = Hashable  # a UDP (host, port) address, a TCP client, or None for point-to-point links

RECONNECT_BACKOFF_MIN_S = 0.5
RECONNECT_BACKOFF_MAX_S = 5.0
# Peers remembered per listening link; beyond this the longest silent one is forgotten.
MAX_PEERS = 64


class FrameSink(Protocol):
    """What a transport reports to its link; every call happens on the event loop."""

    def frame_received(self, msg: mavlink.MAVLink_message, peer: Peer) -> None: ...

    def bad_frames_received(self, count: int) -> None: ...

    def bytes_received(self, count: int) -> None: ...

    def connection_changed(self, connected: bool) -> None: ...


class FrameDecoder:
    """pymavlink's parser in robust mode: garbage, bad CRC and truncation become counts.

    ``codec`` (a link's signing codec) checks signatures too; the frames it rejects are
    neither delivered nor bad frames: the link's signing counts them."""

    def __init__(self, codec: mavlink.MAVLink | None = None) -> None:
        self._mav = codec if codec is not None else mavlink.MAVLink(None)
        self._mav.robust_parsing = True

    def feed(self, data: bytes) -> tuple[list[mavlink.MAVLink_message], int]:
        """Decode what ``data`` completes; return (good frames, bad frame count)."""
        parsed = self._mav.parse_buffer(data) or []
        good = [m for m in parsed if not isinstance(m, mavlink.MAVLink_bad_data)]
        unsigned = sum(1 for m in parsed if getattr(m, "reason", None) == _SIGNATURE_REJECTED)
        return good, len(parsed) - len(good) - unsigned

    def discard_partial(self) -> bool:
        """Forget a frame still incomplete; True when there was one (it was truncated)."""
        if self._mav.buf_len() == 0:
            return False
        self._mav.buf = bytearray()
        self._mav.buf_index = 0
        self._mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        return True


# pymavlink's reason for a frame its signing state rejected
_SIGNATURE_REJECTED = "Invalid signature"

# Sees each good frame before the sink; False drops it (the hook counts it).
FrameHook = Callable[[mavlink.MAVLink_message, Peer], bool | None]


def deliver(
    sink: FrameSink,
    decoder: FrameDecoder,
    data: bytes,
    peer: Peer,
    *,
    datagram: bool,
    before_each: FrameHook | None = None,
) -> None:
    """Decode ``data`` and report it; ``before_each`` sees every good frame before the sink."""
    sink.bytes_received(len(data))
    frames, bad = decoder.feed(data)
    if datagram and decoder.discard_partial():
        bad += 1
    if bad:
        sink.bad_frames_received(bad)
    for msg in frames:
        if before_each is not None and before_each(msg, peer) is False:
            continue
        sink.frame_received(msg, peer)


def host_port(address: Any) -> tuple[str, int]:
    """(host, port) of a socket address, IPv4 or IPv6 (which has two more fields)."""
    host, port = address[:2]
    return str(host), int(port)


class PeerRouter:
    """Sends a frame for system S to the peer S was last heard from; others to every peer.

    Peers heard from longer than ``expiry_s`` ago get no broadcasts (None: they always do).
    Every call happens on the event loop, whose clock ages them.
    """

    def __init__(self, expiry_s: float | None, clock: Callable[[], float] = loop_time_s) -> None:
        self._expiry_s = expiry_s
        self._clock = clock
        self._peer_by_system: dict[int, Peer] = {}
        self._last_heard: dict[Peer, float] = {}

    def heard(self, peer: Peer, src_system: int) -> bool:
        """Note a frame from ``peer``; True when the peer was not known before."""
        self._peer_by_system[src_system] = peer
        is_new = self._last_heard.pop(peer, None) is None  # re-insert: order is recency
        self._last_heard[peer] = self._clock()
        if len(self._last_heard) > MAX_PEERS:
            self.forget(next(iter(self._last_heard)))
        return is_new

    def forget(self, peer: Peer) -> None:
        self._last_heard.pop(peer, None)
        for system in [s for s, p in self._peer_by_system.items() if p == peer]:
            del self._peer_by_system[system]

    def silent_s(self, peer: Peer) -> float:
        """Seconds since ``peer`` was last heard (infinite for a peer not known)."""
        last = self._last_heard.get(peer)
        return float("inf") if last is None else self._clock() - last

    def peer_of(self, target_system: int | None) -> Peer | None:
        """The peer a targeted frame should go to; None for broadcasts and unknown systems."""
        if not target_system:
            return None
        peer = self._peer_by_system.get(target_system)
        return peer if peer in self._last_heard else None

    def every_peer(self) -> list[Peer]:
        """Every peer known, whatever its age: broadcasts sent off the loop, whose clock
        ages peers, go to these."""
        return list(self._last_heard)

    def destinations(self, target_system: int | None) -> list[Peer]:
        peer = self.peer_of(target_system)
        if peer is not None:
            return [peer]
        if not self._last_heard:
            return []
        if self._expiry_s is None:
            return list(self._last_heard)
        oldest_allowed = self._clock() - self._expiry_s
        recent = [p for p, t in self._last_heard.items() if t >= oldest_allowed]
        # Nobody recent: still answer the last one who spoke, as pymavlink's udpin does.
        return recent or [next(reversed(self._last_heard))]


class Transport(ABC):
    """One connection of a link. ``start`` binds or connects; ``write`` never blocks."""

    def __init__(self, address: LinkUrl) -> None:
        self.address = address
        self.reconnects = 0
        # The wait before the next attempt to open a connection that failed or went away.
        self.backoff_s = RECONNECT_BACKOFF_MIN_S
        self._ever_connected = False
        self._sink: FrameSink | None = None
        # makes each decoder's pymavlink codec; a link with signing sets it before start()
        self.codec_factory: Callable[[], mavlink.MAVLink] | None = None

    def _new_decoder(self) -> FrameDecoder:
        return FrameDecoder(self.codec_factory() if self.codec_factory is not None else None)

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

    def input_pending(self) -> bool:
        """Whether bytes wait, received but not read yet (the loop is behind). A transport
        that cannot tell says False."""
        return False

    def thread_writer(self) -> Callable[[bytes, int | None], bool] | None:
        """A write() that threads other than the loop's may call (the setpoint sender
        thread), or None: then the link hands their frames to the loop."""
        return None

    def process_socket(self) -> socket.socket | None:
        """The socket another process may write this transport's frames with (the setpoint
        sender process), or None: that process cannot send for it."""
        return None

    def destinations_of(self, target_system: int | None) -> list[Any] | None:
        """Where a frame for ``target_system`` goes when written with process_socket()
        (None: the socket is connected to its one peer)."""
        return None

    def _opened(self) -> None:
        """A connection is up: count it if it is a reconnect, and retry quickly next time."""
        if self._ever_connected:
            self.reconnects += 1
        self._ever_connected = True
        self.backoff_s = RECONNECT_BACKOFF_MIN_S

    def _waited_in_vain(self) -> None:
        """A wait of ``backoff_s`` after a failed attempt is over: the next wait is longer."""
        self.backoff_s = min(self.backoff_s * 2, RECONNECT_BACKOFF_MAX_S)
