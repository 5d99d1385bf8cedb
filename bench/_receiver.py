"""A stand-in PX4 vehicle for the link benchmarks, in its own process.

It answers on one UDP socket on 127.0.0.1 like a vehicle that talks back to whoever spoke:
HEARTBEAT at 1 Hz (quadrotor, PX4, starting in Hold), COMMAND_ACK ACCEPTED to every command
for it, and DO_SET_MODE switches the mode it reports (so clients that stop streaming when
the vehicle is not in OFFBOARD, as MAVSDK does, keep going). It timestamps each
SET_POSITION_TARGET_LOCAL_NED on arrival (time.perf_counter), per sending
system/component, so clients can be compared with the same clock and socket.

Protocol on stdio, one line each: it prints ``{"event": "ready", "port": N}`` once bound;
``reset`` forgets the arrivals so far; ``report`` prints
``{"arrivals": {"SYS/COMP": [t, ...]}}`` (seconds) for those since the last reset;
``quit`` (or end of input) stops it.
"""

from __future__ import annotations

import json
import selectors
import socket
import sys
import time

from pymavlink.dialects.v20 import development as mavlink

VEHICLE_SYSID = 1
HOLD_CUSTOM_MODE = 0x3040000  # PX4 AUTO_LOITER: main 4, sub 3
HEARTBEAT_PERIOD_S = 1.0


class Receiver:
    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.mav = mavlink.MAVLink(None, srcSystem=VEHICLE_SYSID, srcComponent=1)
        self.decoder = mavlink.MAVLink(None)
        self.decoder.robust_parsing = True
        self.peers: dict[tuple[str, int], None] = {}
        self.custom_mode = HOLD_CUSTOM_MODE
        self.arrivals: dict[str, list[float]] = {}

    @property
    def port(self) -> int:
        return int(self.sock.getsockname()[1])

    def send(self, msg: mavlink.MAVLink_message, addr: tuple[str, int]) -> None:
        frame = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        self.sock.sendto(frame, addr)

    def send_heartbeat(self) -> None:
        base_mode = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        for addr in self.peers:
            self.send(self.mav.heartbeat_encode(
                mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base_mode,
                self.custom_mode, mavlink.MAV_STATE_STANDBY,
            ), addr)

    def read_socket(self) -> None:
        while True:
            try:
                data, addr = self.sock.recvfrom(65536)
            except BlockingIOError:
                return
            arrived = time.perf_counter()
            if addr not in self.peers:
                self.peers[addr] = None
                self.send_heartbeat()
            for msg in self.decoder.parse_buffer(data) or []:
                self.handle(msg, addr, arrived)

    def handle(self, msg: mavlink.MAVLink_message, addr: tuple[str, int], arrived: float) -> None:
        kind = msg.get_type()
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            key = f"{msg.get_srcSystem()}/{msg.get_srcComponent()}"
            self.arrivals.setdefault(key, []).append(arrived)
        elif kind in ("COMMAND_LONG", "COMMAND_INT") and msg.target_system == VEHICLE_SYSID:
            self.send(self.mav.command_ack_encode(
                msg.command, mavlink.MAV_RESULT_ACCEPTED, 0, 0,
                msg.get_srcSystem(), msg.get_srcComponent(),
            ), addr)
            if msg.command == mavlink.MAV_CMD_DO_SET_MODE:
                # PX4: custom_mode = main << 16 | sub << 24, from param2 and param3.
                self.custom_mode = int(msg.param2) << 16 | int(msg.param3) << 24
                self.send_heartbeat()

    def command(self, line: str) -> bool:
        word = line.strip()
        if word == "reset":
            self.arrivals = {}
        elif word == "report":
            print(json.dumps({"arrivals": self.arrivals}), flush=True)
        return word not in ("quit", "")


def main() -> None:
    receiver = Receiver()
    selector = selectors.DefaultSelector()
    selector.register(receiver.sock, selectors.EVENT_READ, "socket")
    selector.register(sys.stdin, selectors.EVENT_READ, "stdin")
    print(json.dumps({"event": "ready", "port": receiver.port}), flush=True)
    next_heartbeat = time.monotonic()
    running = True
    while running:
        timeout = max(0.0, next_heartbeat - time.monotonic())
        for key, _ in selector.select(timeout):
            if key.data == "socket":
                receiver.read_socket()
            else:
                running = receiver.command(sys.stdin.readline())
        if time.monotonic() >= next_heartbeat:
            receiver.send_heartbeat()
            next_heartbeat += HEARTBEAT_PERIOD_S


if __name__ == "__main__":
    main()
