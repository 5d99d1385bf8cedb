"""Byte transports for a link, each turning bytes into decoded MAVLink frames on the event loop.

One module per kind: :mod:`.udp` (``udpin:``, ``udpout:``), :mod:`.tcp` (``tcp:``,
``tcpin:``), :mod:`.serial_port` (``DEVICE:BAUD``) and :mod:`.replay` (``tlog:``), all on
:mod:`.base`. Decoding (pymavlink, ``development`` dialect, MAVLink 1 and 2) happens on the
loop, with one decoder per byte stream: a TCP connection, a serial port, or a single UDP
datagram.

Writes never block: a transport that cannot take a frame now (no peer yet, not connected,
a full socket backlog) drops it and says so by returning False.
"""

from __future__ import annotations

from server.link.codec.urls import LinkUrl
from server.link.transports.base import FrameDecoder, FrameSink, Peer, Transport
from server.link.transports.replay import ReplayTransport
from server.link.transports.serial_port import SerialTransport
from server.link.transports.tcp import TcpClientTransport, TcpServerTransport
from server.link.transports.udp import UdpInTransport, UdpOutTransport

__all__ = [
    "FrameDecoder",
    "FrameSink",
    "Peer",
    "ReplayTransport",
    "SerialTransport",
    "TcpClientTransport",
    "TcpServerTransport",
    "Transport",
    "UdpInTransport",
    "UdpOutTransport",
    "create_transport",
]

_TRANSPORTS: dict[str, type[Transport]] = {
    "udpin": UdpInTransport,
    "udpout": UdpOutTransport,
    "tcp": TcpClientTransport,
    "tcpin": TcpServerTransport,
    "serial": SerialTransport,
    "tlog": ReplayTransport,
}


def create_transport(address: LinkUrl) -> Transport:
    return _TRANSPORTS[address.kind](address)
