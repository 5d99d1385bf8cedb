"""UDP endpoints of the simulated vehicle: one socket per link, MAVLink 2 on the wire.

Like PX4's UDP links, a link sends to a configured remote port if it has one and
otherwise (and from then on) to whoever sent it the last datagram. Every datagram is
parsed on its own: garbage, truncated frames and bad CRCs are counted and dropped.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeAlias, cast

from pymavlink.dialects.v20 import development as mavlink

from sim.frames import pack_frame
from sim.signing import MAVLINK_MSG_ID_SETUP_SIGNING, VehicleSigning

# pymavlink messages carry their fields as dynamic attributes.
Message: TypeAlias = Any
Address = tuple[str, int]
MessageHandler = Callable[["UdpLink", Message], None]

log = logging.getLogger(__name__)


@dataclass
class LinkCounters:
    """What one link has seen since it opened (for logs, benches and tests)."""

    rx_datagrams: int = 0
    rx_messages: int = 0
    # garbage, truncated frames and bad CRCs: pieces of datagrams that were thrown away
    rx_dropped: int = 0
    tx_messages: int = 0
    # ICMP "port unreachable" while nobody listens on the remote port
    tx_errors: int = 0
    # frames that could not be encoded: skipped so the telemetry loop keeps running
    tx_unpackable: int = 0


class MavlinkCodec:
    """pymavlink's codec used per datagram: sequence numbers out, a fresh parse in."""

    def __init__(self, sysid: int, compid: int, mav: mavlink.MAVLink | None = None) -> None:
        # ``mav``: a signing codec (sim.signing), which signs and checks frames
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

    def decode(self, data: bytes) -> tuple[list[Message], int]:
        """The messages in one datagram and how many pieces of it were unusable."""
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
            return [], 1
        good = [m for m in parsed if not isinstance(m, mavlink.MAVLink_bad_data)]
        # frames the signing refused are counted there, not as broken
        refused = sum(1 for m in parsed if getattr(m, "reason", None) == "Invalid signature")
        self.last_refused = refused
        bad = len(parsed) - len(good) - refused
        if mav.buf_len() > 0:
            bad += 1  # a truncated frame left at the end
        return good, bad


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
    ) -> None:
        self.name = name
        self.remote = remote
        self.counters = LinkCounters()
        self.signing = signing
        self._codec = MavlinkCodec(
            sysid, compid, signing.codec(link_id) if signing is not None else None
        )
        self._on_message = on_message
        self._transport: asyncio.DatagramTransport | None = None
        self.local_port = 0

    @property
    def has_remote(self) -> bool:
        return self.remote is not None and self._transport is not None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.DatagramTransport, transport)
        self.local_port = transport.get_extra_info("sockname")[1]

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable while nobody listens on the remote: expected, keep going.
        self.counters.tx_errors += 1

    def datagram_received(self, data: bytes, addr: Address) -> None:
        self.counters.rx_datagrams += 1
        messages, bad = self._codec.decode(data)
        self.counters.rx_dropped += bad
        if not messages:
            if bad == 0 and self._codec.last_refused == 0:
                self.counters.rx_dropped += 1
            return
        self.remote = (addr[0], addr[1])
        for msg in messages:
            self.counters.rx_messages += 1
            if msg.get_msgId() == MAVLINK_MSG_ID_SETUP_SIGNING:
                # the MAVLink module's own business: never handed on (nor forwarded)
                if self.signing is not None:
                    self.signing.handle_setup_signing(msg)
                continue
            try:
                self._on_message(self, msg)
            except Exception:
                log.exception("%s: handling %s failed", self.name, msg.get_type())

    def send(self, msg: Message) -> None:
        if self._transport is None or self.remote is None:
            return
        try:
            data = self._codec.encode(msg)
        except Exception:  # pymavlink raises struct, value and type errors on bad fields
            self.counters.tx_unpackable += 1
            log.debug("%s: could not pack %s", self.name, msg.get_type(), exc_info=True)
            return
        self._transport.sendto(data, self.remote)
        self.counters.tx_messages += 1

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()
            self._transport = None


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
    _, protocol = await loop.create_datagram_endpoint(
        lambda: UdpLink(name, sysid, compid, on_message, remote, signing, link_id),
        local_addr=(host, local_port),
    )
    return protocol
