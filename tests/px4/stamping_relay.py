"""A UDP relay between SkyHelm and PX4 that timestamps what PX4 is about to receive.

PX4 sends to the relay's vehicle-facing socket (the port PX4's API link talks to), SkyHelm
to its server-facing one; each datagram leaves through the other socket at once. It runs
at real-time priority (SCHED_FIFO 20) and takes the kernel's receive time of every
SkyHelm frame (SO_TIMESTAMPNS), so a busy machine does not blur the figures: the intervals
of SET_POSITION_TARGET_LOCAL_NED are those PX4 receives them at, to the relay's forwarding
delay. It also keeps PX4's HEARTBEAT custom modes (every change, with its time).

    python -m tests.px4.stamping_relay VEHICLE_HOST VEHICLE_PORT

prints ``{"port": N}`` (the server-facing port) once bound; a ``report`` line on stdin
prints ``{"setpoints": [t, ...], "modes": [[t, custom_mode], ...]}`` (Unix seconds) for
what came since the previous report; end of input stops it.
"""

from __future__ import annotations

import json
import os
import select
import socket
import sys
import time

from bench._receiver import SO_TIMESTAMPNS, kernel_receive_time

MAVLINK_STX_V2 = 0xFD
MSG_ID_HEARTBEAT = 0
MSG_ID_SET_POSITION_TARGET_LOCAL_NED = 84
RT_PRIORITY = 20


def _frames(data: bytes) -> list[tuple[int, int, bytes]]:
    """(message id, source component, payload) of each MAVLink 2 frame in a datagram."""
    frames = []
    at = 0
    while at + 12 <= len(data) and data[at] == MAVLINK_STX_V2:
        length, flags = data[at + 1], data[at + 2]
        msg_id = int.from_bytes(data[at + 7:at + 10], "little")
        frames.append((msg_id, data[at + 6], data[at + 10:at + 10 + length]))
        at += 12 + length + (13 if flags & 1 else 0)
    return frames


def main() -> None:
    vehicle_listen = (sys.argv[1], int(sys.argv[2]))
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    except OSError as exc:
        print(f"stamping relay at normal priority: {exc}", file=sys.stderr)
    to_vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    to_vehicle.bind(vehicle_listen)
    to_server = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    to_server.bind(("127.0.0.1", 0))
    to_server.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    vehicle: tuple[str, int] | None = None
    server: tuple[str, int] | None = None
    setpoints: list[float] = []
    modes: list[tuple[float, int]] = []
    print(json.dumps({"port": to_server.getsockname()[1]}), flush=True)
    while True:
        readable, _, _ = select.select([to_vehicle, to_server, sys.stdin], [], [])
        if to_server in readable:
            data, ancillary, _flags, server = to_server.recvmsg(65536, 64)
            arrived = kernel_receive_time(ancillary)
            if vehicle is not None:
                to_vehicle.sendto(data, vehicle)
            if any(f[0] == MSG_ID_SET_POSITION_TARGET_LOCAL_NED for f in _frames(data)):
                setpoints.append(arrived)
        if to_vehicle in readable:
            data, vehicle = to_vehicle.recvfrom(65536)
            if server is not None:
                to_server.sendto(data, server)
            for msg_id, component, payload in _frames(data):
                if msg_id == MSG_ID_HEARTBEAT and component == 1 and len(payload) >= 4:
                    mode = int.from_bytes(payload[:4], "little")
                    if not modes or modes[-1][1] != mode:
                        modes.append((time.time(), mode))
        if sys.stdin in readable:
            line = sys.stdin.readline()
            if not line:
                return
            print(json.dumps({"setpoints": setpoints, "modes": modes}), flush=True)
            setpoints = []
            modes = modes[-1:]


if __name__ == "__main__":
    main()
