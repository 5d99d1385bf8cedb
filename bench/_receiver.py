"""A stand-in PX4 vehicle for the link benchmarks, in its own process.

It answers on one UDP socket on 127.0.0.1 like a vehicle that talks back to whoever spoke:
HEARTBEAT at 1 Hz (quadrotor, PX4, starting in Hold), COMMAND_ACK ACCEPTED to every command
for it, and DO_SET_MODE switches the mode it reports (so clients that stop streaming when
the vehicle is not in OFFBOARD, as MAVSDK does, keep going). It timestamps each
SET_POSITION_TARGET_LOCAL_NED on arrival (the kernel's receive time on Linux), per sending
system/component, so clients can be compared with the same clock and socket. With
``--telemetry-hz N`` it also sends ATTITUDE, LOCAL_POSITION_NED and GLOBAL_POSITION_INT at
N Hz to its peers, so the server has live telemetry to decode and fan out, as with a vehicle.
MANUAL_CONTROL arrivals are kept under ``mc:SYS/COMP``. ``--vehicles N`` stands in for N
vehicles (system ids 1..N, a socket each; their arrivals under ``V:SYS/COMP``),
``--connect PORT`` makes each speak first to a server listening there (udpin), and
``--rt-priority P`` timestamps at real-time priority (SCHED_FIFO P), as a vehicle on its own
hardware is untouched by the load of the computer that sends to it.

Protocol on stdio, one line each: it prints ``{"event": "ready", "port": N}`` once bound;
``reset`` forgets the arrivals so far; ``report`` prints
``{"arrivals": {"SYS/COMP": [t, ...]}}`` (seconds) for those since the last reset;
``quit`` (or end of input) stops it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import selectors
import socket
import struct
import sys
import time

from pymavlink.dialects.v20 import development as mavlink

VEHICLE_SYSID = 1
HOLD_CUSTOM_MODE = 0x3040000  # PX4 AUTO_LOITER: main 4, sub 3
HEARTBEAT_PERIOD_S = 1.0
# Linux: the kernel stamps each datagram as it is queued (SO_TIMESTAMPNS, struct timespec),
# so an arrival time does not wait for this process to be scheduled or to finish sending
SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("@qq")


def kernel_receive_time(ancillary: list[tuple[int, int, bytes]]) -> float:
    """The kernel's receive time (Unix seconds) in recvmsg()'s ancillary data of a socket
    with SO_TIMESTAMPNS on; now, where it is missing."""
    for level, kind, value in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
            seconds, nanoseconds = _TIMESPEC.unpack(value[: _TIMESPEC.size])
            return float(seconds + nanoseconds * 1e-9)
    return time.time()


class Receiver:
    def __init__(self, sysid: int = VEHICLE_SYSID, key_prefix: str = "") -> None:
        self.sysid = sysid
        self.key_prefix = key_prefix
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.kernel_stamps = sys.platform == "linux"
        if self.kernel_stamps:
            self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=1)
        self.decoder = mavlink.MAVLink(None)
        self.decoder.robust_parsing = True
        self.peers: dict[tuple[str, int], None] = {}
        self.custom_mode = HOLD_CUSTOM_MODE
        self.arrivals: dict[str, list[float]] = {}
        self.started = time.monotonic()

    def send_telemetry(self) -> None:
        t = time.monotonic() - self.started
        boot_ms = int(t * 1000)
        north, east = 10 * math.cos(t / 10), 10 * math.sin(t / 10)
        for addr in self.peers:
            self.send(self.mav.attitude_encode(boot_ms, 0.01, -0.02, t / 10 % 6.28, 0, 0, 0.1),
                      addr)
            self.send(self.mav.local_position_ned_encode(boot_ms, north, east, -5.0, 0, 0, 0),
                      addr)
            self.send(self.mav.global_position_int_encode(
                boot_ms, 473977420 + int(north * 90), 85455940 + int(east * 130), 493000,
                5000, 0, 0, 0, 0), addr)

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
                data, ancillary, _flags, addr = self.sock.recvmsg(65536, 64)
            except BlockingIOError:
                return
            arrived = kernel_receive_time(ancillary)
            if addr not in self.peers:
                self.peers[addr] = None
                self.send_heartbeat()
            for msg in self.decoder.parse_buffer(data) or []:
                self.handle(msg, addr, arrived)

    def handle(self, msg: mavlink.MAVLink_message, addr: tuple[str, int], arrived: float) -> None:
        kind = msg.get_type()
        if kind in ("SET_POSITION_TARGET_LOCAL_NED", "MANUAL_CONTROL"):
            key = (f"{self.key_prefix}{'mc:' if kind == 'MANUAL_CONTROL' else ''}"
                   f"{msg.get_srcSystem()}/{msg.get_srcComponent()}")
            self.arrivals.setdefault(key, []).append(arrived)
        elif kind in ("COMMAND_LONG", "COMMAND_INT") and msg.target_system == self.sysid:
            self.send(self.mav.command_ack_encode(
                msg.command, mavlink.MAV_RESULT_ACCEPTED, 0, 0,
                msg.get_srcSystem(), msg.get_srcComponent(),
            ), addr)
            if msg.command == mavlink.MAV_CMD_DO_SET_MODE:
                # PX4: custom_mode = main << 16 | sub << 24, from param2 and param3.
                self.custom_mode = int(msg.param2) << 16 | int(msg.param3) << 24
                self.send_heartbeat()

def command(receivers: list[Receiver], line: str) -> bool:
    word = line.strip()
    if word == "reset":
        for receiver in receivers:
            receiver.arrivals = {}
    elif word == "report":
        arrivals = {k: v for r in receivers for k, v in r.arrivals.items()}
        print(json.dumps({"arrivals": arrivals}), flush=True)
    return word not in ("quit", "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--telemetry-hz", type=float, default=0.0)
    parser.add_argument("--vehicles", type=int, default=1)
    parser.add_argument("--connect", type=int, default=0, help="a server's udpin port")
    parser.add_argument("--rt-priority", type=int, default=0)
    args = parser.parse_args()
    if args.rt_priority > 0:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.rt_priority))
    receivers = [Receiver(sysid, f"{sysid}:" if args.vehicles > 1 else "")
                 for sysid in range(1, args.vehicles + 1)]
    selector = selectors.DefaultSelector()
    for receiver in receivers:
        selector.register(receiver.sock, selectors.EVENT_READ, receiver)
        if args.connect:
            receiver.peers[("127.0.0.1", args.connect)] = None
    selector.register(sys.stdin, selectors.EVENT_READ, "stdin")
    print(json.dumps({"event": "ready", "port": receivers[0].port}), flush=True)
    next_heartbeat = time.monotonic()
    telemetry_period_s = 1.0 / args.telemetry_hz if args.telemetry_hz > 0 else math.inf
    next_telemetry = time.monotonic() + telemetry_period_s
    running = True
    while running:
        timeout = max(0.0, min(next_heartbeat, next_telemetry) - time.monotonic())
        for key, _ in selector.select(timeout):
            if key.data == "stdin":
                running = command(receivers, sys.stdin.readline())
            else:
                key.data.read_socket()
        if time.monotonic() >= next_heartbeat:
            for receiver in receivers:
                receiver.send_heartbeat()
            next_heartbeat += HEARTBEAT_PERIOD_S
        if time.monotonic() >= next_telemetry:
            for receiver in receivers:
                receiver.send_telemetry()
            next_telemetry = max(next_telemetry + telemetry_period_s, time.monotonic())


if __name__ == "__main__":
    main()
