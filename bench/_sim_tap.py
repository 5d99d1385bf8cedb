"""Simulated vehicles that time the setpoints they receive, for bench.many_vehicles.

One process runs a SimCluster (the same vehicles `python -m sim` runs: instance i, sysid
i+1, ephemeral ports on 127.0.0.1) and observes its API links: every
SET_POSITION_TARGET_LOCAL_NED is timed with the kernel's receive timestamp of its datagram
(SIOCGSTAMP, read right after asyncio's recvfrom handed the datagram over), so the time the
process's loop spent stepping physics before it read the socket is not in the figures: they
are the arrival times at the vehicle's socket, as PX4's receiver would see them.

Protocol on stdio, one line each: it prints ``{"event": "ready", "instances": [...]}`` once
bound (as `python -m sim --ready-json` does); ``reset`` forgets the arrivals so far and
starts the CPU count; ``report`` prints ``{"arrivals": {"SYSID": [t, ...]}, "cpu_s": ..,
"wall_s": ..}``; end of input stops it.

    python -m bench._sim_tap --first 0 --count 16
"""

from __future__ import annotations

import argparse
import asyncio
import fcntl
import json
import socket
import struct
import sys
import time
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from sim.mavlink.endpoint import UdpLink
from sim.process.runner import SimCluster

SIOCGSTAMP = 0x8906  # linux/sockios.h: struct timeval of the last packet read
_TIMEVAL = struct.Struct("@ll")


class ArrivalTap:
    def __init__(self) -> None:
        self.arrivals: dict[int, list[float]] = {}
        self.cpu0_s = time.process_time()
        self.wall0_s = time.monotonic()
        self.sim0_s = 0.0

    def watch(self, sysid: int, link: UdpLink) -> None:
        transport = link._transport  # the link's own socket: the bench reads its timestamps
        assert transport is not None
        sock: socket.socket = transport.get_extra_info("socket")
        fd = sock.fileno()
        times = self.arrivals.setdefault(sysid, [])

        def observe(_sender: Any, msg: Any) -> None:
            if msg.get_msgId() == mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED:
                seconds, micros = _TIMEVAL.unpack(fcntl.ioctl(fd, SIOCGSTAMP, bytes(16)))
                times.append(seconds + micros * 1e-6)

        link.observe(observe)

    def reset(self, cluster: SimCluster) -> None:
        for times in self.arrivals.values():
            times.clear()
        self.cpu0_s = time.process_time()
        self.wall0_s = time.monotonic()
        self.sim0_s = cluster.instances[0].vehicle.now_s
        cluster.loop_stats.reset()

    def report(self, cluster: SimCluster) -> dict[str, Any]:
        wall_s = time.monotonic() - self.wall0_s
        return {
            "arrivals": {str(k): v for k, v in self.arrivals.items()},
            "cpu_s": time.process_time() - self.cpu0_s,
            "wall_s": wall_s,
            # how well the vehicles kept real time: sim seconds per wall second, the
            # stepping loop's worst lateness
            "sim_over_wall": (cluster.instances[0].vehicle.now_s - self.sim0_s) / wall_s,
            "loop_max_lag_s": cluster.loop_stats.max_lag_s,
        }


async def run(first: int, count: int) -> None:
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    tap = ArrivalTap()
    async with SimCluster(count=count, instance=first) as cluster:
        for inst in cluster.instances:
            tap.watch(inst.sysid, inst.api_link)
        ready = {
            "event": "ready",
            "instances": [
                {"instance": i.instance, "sysid": i.sysid, "api_local_port": i.api_local_port,
                 "gcs_local_port": i.gcs_local_port}
                for i in cluster.instances
            ],
        }
        print(json.dumps(ready), flush=True)
        while line := (await reader.readline()).decode().strip():
            if line == "reset":
                tap.reset(cluster)
            elif line == "report":
                print(json.dumps(tap.report(cluster)), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--count", type=int, default=1)
    args = parser.parse_args()
    asyncio.run(run(args.first, args.count))


if __name__ == "__main__":
    main()
