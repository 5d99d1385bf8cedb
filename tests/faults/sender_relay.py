"""A UDP relay between SkyHelm and the simulated vehicle that times what the vehicle receives.

SkyHelm sends to its server-facing socket, which keeps the kernel's receive time of every
datagram (SO_TIMESTAMPNS: a busy test process does not move it); the datagram goes on to
the vehicle at once. What the vehicle sends back goes to the server's last address, and its
HEARTBEAT custom modes are kept (each, with its time). A thread of its own does it.
"""

from __future__ import annotations

import select
import socket
import threading
import time
from dataclasses import dataclass

from bench._receiver import SO_TIMESTAMPNS, kernel_receive_time

MAVLINK_STX_V2 = 0xFD


@dataclass(frozen=True)
class Heard:
    """One MAVLink 2 frame from the server, as the vehicle is about to receive it."""

    unix_s: float  # the kernel's receive time at the relay
    msg_id: int
    seq: int
    sysid: int
    compid: int
    payload: bytes = b""  # as on the wire (MAVLink 2 trims its trailing zeros)


def _frames(data: bytes) -> list[tuple[int, int, int, int, bytes]]:
    """(message id, sequence, system, component, payload) of each MAVLink 2 frame."""
    frames = []
    at = 0
    while at + 12 <= len(data) and data[at] == MAVLINK_STX_V2:
        length, flags = data[at + 1], data[at + 2]
        msg_id = int.from_bytes(data[at + 7:at + 10], "little")
        frames.append((msg_id, data[at + 4], data[at + 5], data[at + 6],
                       data[at + 10:at + 10 + length]))
        at += 12 + length + (13 if flags & 1 else 0)
    return frames


class SenderRelay:
    def __init__(self, vehicle: tuple[str, int]) -> None:
        self.vehicle = vehicle
        self.to_server = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.to_server.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
        self.to_server.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        self.to_server.bind(("127.0.0.1", 0))
        self.to_vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.to_vehicle.bind(("127.0.0.1", 0))
        self.heard: list[Heard] = []
        self.modes: list[tuple[float, int]] = []  # (unix s, custom_mode) of each HEARTBEAT
        self._server: tuple[str, int] | None = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sender-relay", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return int(self.to_server.getsockname()[1])

    def since(self, unix_s: float, msg_id: int) -> list[Heard]:
        return [h for h in self.heard if h.unix_s >= unix_s and h.msg_id == msg_id]

    def _run(self) -> None:
        poller = select.poll()
        poller.register(self.to_server, select.POLLIN)
        poller.register(self.to_vehicle, select.POLLIN)
        while not self._done.is_set():
            for fd, _ in poller.poll(100):
                if fd == self.to_server.fileno():
                    data, ancillary, _flags, self._server = self.to_server.recvmsg(65536, 64)
                    arrived = kernel_receive_time(ancillary)
                    self.to_vehicle.sendto(data, self.vehicle)
                    for msg_id, seq, sysid, compid, payload in _frames(data):
                        self.heard.append(Heard(arrived, msg_id, seq, sysid, compid, payload))
                else:
                    data = self.to_vehicle.recv(65536)
                    if self._server is not None:
                        self.to_server.sendto(data, self._server)
                    for msg_id, _, _, compid, payload in _frames(data):
                        if msg_id == 0 and compid == 1 and len(payload) >= 4:
                            mode = int.from_bytes(payload[:4], "little")
                            self.modes.append((time.time(), mode))

    def close(self) -> None:
        self._done.set()
        self._thread.join(5.0)
        self.to_server.close()
        self.to_vehicle.close()
