"""UDP endpoints of the simulated vehicle: one socket per link, MAVLink 2 on the wire.

Where a link sends, after PX4's mavlink_receiver (the client source address is set once):

- With a configured remote port, it sends there until the first checked frame arrives;
  that sender is its partner from then on and nobody else is ever followed.
- Without one, it answers the sender of the first checked frame, and moves to a new sender
  only once its partner has been silent for ``PEER_HANDOVER_S`` (a restarted ground station
  on a new port is found again; a stranger cannot take a partner's telemetry while the
  partner talks).

Every datagram is parsed on its own. Garbage, truncated frames and bad CRCs are counted
and dropped. A frame of an id pymavlink's dialect lacks (UNKNOWN_<id>) has a checksum
nobody here can check, unless the id is one the vehicle takes (REQUEST_EVENT): such frames
are counted as unverified and dropped; they never choose the partner, as random bytes often
parse as one.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeAlias, cast

from pymavlink.dialects.v20 import development as mavlink

from sim.lib.events import MAVLINK_MSG_ID_REQUEST_EVENT
from sim.lib.mavlink_custom import LinkNodeStatusMessage
from sim.mavlink.frames import pack_frame
from sim.mavlink.signing import MAVLINK_MSG_ID_SETUP_SIGNING, VehicleSigning

# pymavlink messages carry their fields as dynamic attributes.
Message: TypeAlias = Any
Address = tuple[str, int]
MessageHandler = Callable[["UdpLink", Message], None]

# asked of the OS for each link socket (granted up to net.core.rmem_max)
RECEIVE_BUFFER_BYTES = 4 * 1024 * 1024
# asyncio hands a datagram endpoint one datagram per turn of the loop; a vehicle whose loop
# turns slowly (its steps on a starved core) then falls behind its input without bound, a
# command answered seconds late behind setpoints that waited in the buffer. Every datagram
# waiting is read at each turn, as PX4's receiver reads its socket dry, up to this many.
DATAGRAMS_PER_TURN = 256
_MAX_DATAGRAM_BYTES = 65535

# A link without a configured remote follows a new sender once its partner is this quiet.
PEER_HANDOVER_S = 2.0
# Ids outside pymavlink's dialect the vehicle takes, with their CRC extra (PX4's generated
# common headers: MAVLINK_MSG_ID_REQUEST_EVENT_CRC).
MAVLINK_MSG_ID_REQUEST_EVENT_CRC = 33
_CHECKABLE_UNKNOWN_CRC_EXTRA: dict[int, int] = {
    MAVLINK_MSG_ID_REQUEST_EVENT: MAVLINK_MSG_ID_REQUEST_EVENT_CRC,
}
_MAVLINK2_HEADER_LEN = 10
_MAVLINK1_HEADER_LEN = 6
_MAVLINK_SIGNATURE_LEN = 13

log = logging.getLogger(__name__)


@dataclass
class LinkCounters:
    """What one link has seen since it opened (for logs, benches and tests)."""

    rx_datagrams: int = 0
    rx_messages: int = 0
    # garbage, truncated frames and bad CRCs: pieces of datagrams that were thrown away
    rx_dropped: int = 0
    # frames of ids outside the dialect whose checksum cannot be checked: thrown away
    rx_unverified: int = 0
    # datagrams with a checked frame from someone other than the partner (never followed)
    rx_from_strangers: int = 0
    tx_messages: int = 0
    # ICMP "port unreachable" while nobody listens on the remote port
    tx_errors: int = 0
    # frames that could not be encoded: skipped so the telemetry loop keeps running
    tx_unpackable: int = 0
    # frames received and found missing by sequence number, counted as PX4's
    # MavlinkReceiver::update_rx_stats does (a repeated number counts 254 missing, as there)
    # and reported in this link's LINK_NODE_STATUS
    rx_seq_received: int = 0
    rx_seq_lost: int = 0


class MavlinkCodec:
    """pymavlink's codec used per datagram: sequence numbers out, a fresh parse in."""

    def __init__(self, sysid: int, compid: int, mav: mavlink.MAVLink | None = None) -> None:
        # ``mav``: a signing codec (sim.mavlink.signing), which signs and checks frames
        self._mav = mav if mav is not None else mavlink.MAVLink(
            None, srcSystem=sysid, srcComponent=compid
        )
        self._mav.robust_parsing = True
        self._sysid = sysid
        self._compid = compid
        self.last_refused = 0  # frames of the last datagram the signing refused

    def encode(self, msg: Message) -> bytes:
        mav = self._mav
        # pack_frame writes unsigned frames only; pymavlink signs
        data = None if mav.signing.sign_outgoing else pack_frame(
            msg, mav.seq, self._sysid, self._compid
        )
        if data is None:
            data = msg.pack(mav)
        mav.seq = (mav.seq + 1) % 256
        return data

    def decode(self, data: bytes) -> tuple[list[Message], int, int]:
        """The messages in one datagram, how many pieces of it were unusable and how many
        frames could not be checked (UNKNOWN_<id> of ids the vehicle does not take)."""
        mav = self._mav
        self.last_refused = 0
        # A datagram never continues in the next one: forget any partial frame.
        mav.buf = bytearray()
        mav.buf_index = 0
        mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        mav.have_prefix_error = False
        try:
            parsed = mav.parse_buffer(data) or []
        except Exception:  # pymavlink raises MAVError and struct/index errors on bad input
            return [], 1, 0
        good = [m for m in parsed if not isinstance(m, mavlink.MAVLink_bad_data)]
        # frames the signing refused are counted there, not as broken
        refused = sum(1 for m in parsed if getattr(m, "reason", None) == "Invalid signature")
        self.last_refused = refused
        bad = len(parsed) - len(good) - refused
        if mav.buf_len() > 0:
            bad += 1  # a truncated frame left at the end
        checked = [m for m in good if _checked(m)]
        return checked, bad, len(good) - len(checked)


def _checked(msg: Message) -> bool:
    """Whether a parsed frame's checksum was checked: always for the dialect's ids (pymavlink
    drops bad CRCs), for UNKNOWN_<id> only when the id's CRC extra is known here."""
    if not isinstance(msg, mavlink.MAVLink_unknown):
        return True
    return unknown_frame_crc_ok(bytes(msg.get_msgbuf()))


def unknown_frame_crc_ok(frame: bytes) -> bool:
    """True when a raw frame's id is one the vehicle takes and its checksum holds."""
    if len(frame) < 8:
        return False
    if frame[0] == mavlink.PROTOCOL_MARKER_V2:
        if len(frame) < _MAVLINK2_HEADER_LEN + 2:
            return False
        header_len = _MAVLINK2_HEADER_LEN
        msg_id = frame[7] | frame[8] << 8 | frame[9] << 16
        signature_len = _MAVLINK_SIGNATURE_LEN if frame[2] & mavlink.MAVLINK_IFLAG_SIGNED else 0
    else:
        header_len = _MAVLINK1_HEADER_LEN
        msg_id = frame[5]
        signature_len = 0
    crc_extra = _CHECKABLE_UNKNOWN_CRC_EXTRA.get(msg_id)
    end = header_len + frame[1]
    if crc_extra is None or len(frame) != end + 2 + signature_len:
        return False
    crc = mavlink.x25crc(frame[1:end])
    crc.accumulate(bytes([crc_extra]))
    return bool(crc.crc == frame[end] | frame[end + 1] << 8)


class UdpLink(asyncio.DatagramProtocol):
    """One MAVLink link on one UDP socket."""

    def __init__(
        self,
        name: str,
        sysid: int,
        compid: int,
        on_message: MessageHandler,
        remote: Address | None = None,
        signing: VehicleSigning | None = None,
        link_id: int = 0,
        sock: socket.socket | None = None,
    ) -> None:
        self.name = name
        # the endpoint's own socket, read dry at each turn (none: one datagram a turn)
        self._sock = sock
        self.remote = remote
        # a configured remote is replaced once, by the first checked frame's sender
        self._partner_set = False
        self._follows_senders = remote is None
        self._partner_heard_s = -math.inf
        self.counters = LinkCounters()
        self.signing = signing
        self._codec = MavlinkCodec(
            sysid, compid, signing.codec(link_id) if signing is not None else None
        )
        self._on_message = on_message
        self._transport: asyncio.DatagramTransport | None = None
        self._observers: list[Callable[[Address, Message], None]] = []
        self._last_seq: dict[tuple[int, int], int] = {}
        self.local_port = 0

    def observe(self, observer: Callable[[Address, Message], None]) -> None:
        """Also show every taken message and its sender to ``observer`` (benches, tests)."""
        self._observers.append(observer)

    @property
    def has_remote(self) -> bool:
        return self.remote is not None and self._transport is not None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.DatagramTransport, transport)
        # A vehicle in Python shares its cores with whatever else runs: a receive buffer
        # wider than the OS's default (~256 datagrams) keeps a stall of its loop from
        # losing the ground's setpoints and commands (PX4 in C never stalls so).
        sock = transport.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
        self.local_port = transport.get_extra_info("sockname")[1]

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None
        self._sock = None

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable while nobody listens on the remote: expected, keep going.
        self.counters.tx_errors += 1

    def datagram_received(self, data: bytes, addr: Address) -> None:
        self._take(data, addr)
        for _ in range(DATAGRAMS_PER_TURN - 1):
            sock = self._sock  # None once closed, also by a handler of the last datagram
            if sock is None:
                return
            try:
                data, addr = sock.recvfrom(_MAX_DATAGRAM_BYTES)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # an ICMP error queued on the socket, as asyncio reports it
                self.error_received(exc)
                continue
            self._take(data, addr)

    def _take(self, data: bytes, addr: Address) -> None:
        self.counters.rx_datagrams += 1
        messages, bad, unverified = self._codec.decode(data)
        self.counters.rx_dropped += bad
        self.counters.rx_unverified += unverified
        if not messages:
            if bad == 0 and unverified == 0 and self._codec.last_refused == 0:
                self.counters.rx_dropped += 1
            return
        sender = (addr[0], addr[1])
        self._heard_from(sender)
        for msg in messages:
            self.counters.rx_messages += 1
            self._count_sequence(msg)
            for observer in self._observers:
                observer(sender, msg)
            if msg.get_msgId() == MAVLINK_MSG_ID_SETUP_SIGNING:
                # the MAVLink module's own business: never handed on (nor forwarded)
                if self.signing is not None:
                    self.signing.handle_setup_signing(msg)
                continue
            try:
                self._on_message(self, msg)
            except Exception:
                log.exception("%s: handling %s failed", self.name, msg.get_type())

    def _count_sequence(self, msg: Message) -> None:
        key = (msg.get_srcSystem(), msg.get_srcComponent())
        seq = msg.get_seq()
        last = self._last_seq.get(key)
        self._last_seq[key] = seq
        self.counters.rx_seq_received += 1
        if last is not None:
            expected = (last + 1) % 256
            self.counters.rx_seq_lost += seq - expected if seq >= expected else seq + 255 - expected

    def _heard_from(self, sender: Address) -> None:
        """A datagram with a checked frame came from ``sender``: is it the partner now?"""
        now_s = time.monotonic()
        if sender == self.remote:
            self._partner_set = True
            self._partner_heard_s = now_s
            return
        if self._follows_senders:
            taken = self.remote is not None and now_s - self._partner_heard_s < PEER_HANDOVER_S
        else:
            taken = self._partner_set
        if taken:
            self.counters.rx_from_strangers += 1
            return
        self.remote = sender
        self._partner_set = True
        self._partner_heard_s = now_s

    def send(self, msg: Message) -> None:
        if self._transport is None or self.remote is None:
            return
        if isinstance(msg, LinkNodeStatusMessage):
            msg = self._own_node_status(msg)
        try:
            data = self._codec.encode(msg)
        except Exception:  # pymavlink raises struct, value and type errors on bad fields
            self.counters.tx_unpackable += 1
            log.debug("%s: could not pack %s", self.name, msg.get_type(), exc_info=True)
            return
        self._transport.sendto(data, self.remote)
        self.counters.tx_messages += 1

    def _own_node_status(self, msg: Message) -> Message:
        """LINK_NODE_STATUS is per link in PX4 (each MAVLink instance reports its own)."""
        return LinkNodeStatusMessage(
            msg.timestamp, 0, 0, self.counters.tx_messages, self.counters.rx_seq_received,
            self.counters.rx_seq_lost, 0, 0, 0, msg.tx_buf, msg.rx_buf,
        )

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()
            self._transport = None
        self._sock = None


async def open_link(
    name: str,
    sysid: int,
    compid: int,
    on_message: MessageHandler,
    host: str,
    local_port: int,
    remote_port: int | None,
    signing: VehicleSigning | None = None,
    link_id: int = 0,
) -> UdpLink:
    """Bind host:local_port (0 = ephemeral) and return the link once bound."""
    loop = asyncio.get_running_loop()
    remote = (host, remote_port) if remote_port else None
    family, kind, proto, _, address = socket.getaddrinfo(host, local_port,
                                                         type=socket.SOCK_DGRAM)[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.bind(address)
        sock.setblocking(False)
        _, protocol = await loop.create_datagram_endpoint(
            lambda: UdpLink(name, sysid, compid, on_message, remote, signing, link_id, sock),
            sock=sock,
        )
    except BaseException:
        sock.close()
        raise
    return protocol
