"""The Foxglove process: `python -m server.foxglove.worker [--port N]`. It runs the SDK's
WebSocket server (on 127.0.0.1) and the MCAP writers, and turns what the server sends it
(wire.py) into their channels: it decodes and encodes every frame here, so none of that,
nor the SDK's calls (which hold the GIL, sometimes for milliseconds while a client is
served), happens in the server's process, whose GIL the setpoint sender thread needs.
It ends when its stdin does, after closing the MCAP files. Every MCAP_FLUSH_S it finishes
the MCAP files' current chunks (a thread of its own, also when no record comes), so a crash
loses at most about that much of a recording (its size-bound chunks held ~10 s)."""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
import time
import traceback
from typing import BinaryIO

import foxglove
from foxglove.messages import LogLevel
from pymavlink.dialects.v20 import development as mavlink

from server.foxglove import wire
from server.foxglove.channels import LINK_METADATA, LinkChannels
from server.foxglove.convert import decode_frame
from server.foxglove.router import FrameRouter

# How often the vehicles' state and health channels are looked at for readers.
READER_CHECK_S = 0.25
MESSAGE_BACKLOG = 4096
# The MCAP files' chunks are finished at least this often: what a crash can lose.
MCAP_FLUSH_S = 0.5
_LEVELS = {level.value: level for level in (
    LogLevel.Unknown, LogLevel.Debug, LogLevel.Info, LogLevel.Warning, LogLevel.Error,
    LogLevel.Fatal,
)}  # fmt: skip


class Worker:
    def __init__(self, port: int | None, out: BinaryIO) -> None:
        self.context = foxglove.Context()
        self.server = None
        if port is not None:
            self.server = foxglove.start_server(
                name="SkyHelm", host="127.0.0.1", port=port, context=self.context,
                message_backlog_size=MESSAGE_BACKLOG,
            )
        self.out = out
        self.routers: list[FrameRouter] = []
        self.writers: list[foxglove.MCAPWriter] = []
        self.codec = mavlink.MAVLink(None)
        self.vehicles: list[tuple[int, foxglove.Channel, foxglove.Channel]] = []
        self.readers: frozenset[int] = frozenset()
        self.checked_s = 0.0
        self.clock = time.monotonic  # the flushes' clock
        self.flushed_s = self.clock()
        self.failed = False
        # handle() and the flushing thread take turns with the writers
        self.lock = threading.Lock()
        self.say({"ready": self.server.port if self.server is not None else None})

    def say(self, message: dict[str, object]) -> None:
        self.out.write(json.dumps(message).encode() + b"\n")
        self.out.flush()

    def handle(self, kind: int, link: int, argument: int, time_s: float, payload: bytes) -> None:
        time_ns = int(time_s * 1e9)
        if kind == wire.FRAME:
            msg = decode_frame(self.codec, payload)
            if msg is not None:
                self.routers[link].frame(msg, bool(argument), time_s)
        elif kind in (wire.STATE, wire.HEALTH):
            vehicle = self.routers[link].channels.vehicle(argument)
            channel = vehicle.state if kind == wire.STATE else vehicle.health
            if channel.has_sinks():
                channel.base.log(payload, time_ns)
        elif kind == wire.EVENT:
            sysid, level, name, text = json.loads(payload)
            self.routers[link].derived(sysid).log(
                _LEVELS.get(level, LogLevel.Unknown), text, name, time_ns)
        elif kind == wire.VEHICLE:
            vehicle = self.routers[link].channels.vehicle(argument)
            self.vehicles.append((argument, vehicle.state, vehicle.health))
        elif kind == wire.LINK:
            self.add_link(**json.loads(payload))
        self.check_readers()

    def add_link(self, name: str, mcap: str | None) -> None:
        self.routers.append(FrameRouter(LinkChannels(self.context, name)))
        if mcap is not None:
            def this_link(channel: foxglove.ChannelDescriptor) -> bool:
                return channel.metadata.get(LINK_METADATA) == name

            self.writers.append(
                foxglove.open_mcap(mcap, context=self.context, channel_filter=this_link))

    def check_readers(self) -> None:
        now_s = time.monotonic()
        if now_s - self.checked_s < READER_CHECK_S:
            return
        self.checked_s = now_s
        readers = frozenset(
            sysid for sysid, state, health in self.vehicles
            if state.has_sinks() or health.has_sinks()
        )
        if readers != self.readers:
            self.readers = readers
            self.say({"readers": sorted(readers)})

    def flush_when_due(self) -> None:
        """Finishes the MCAP files' chunks when the last was finished MCAP_FLUSH_S ago; the
        caller holds the lock."""
        now_s = self.clock()
        if now_s - self.flushed_s < MCAP_FLUSH_S:
            return
        self.flushed_s = now_s
        for writer in self.writers:
            writer.flush()

    def flush_periodically(self) -> None:
        """For quiet times: while records come, serve() flushes between them, on time (a
        thread waking to take the lock from a busy reader can wait out a whole backlog)."""
        while True:
            time.sleep(MCAP_FLUSH_S / 5)
            with self.lock:
                self.flush_when_due()

    def close(self) -> None:
        for writer in self.writers:
            writer.close()
        self.writers.clear()
        for router in self.routers:
            router.channels.close()
        if self.server is not None:
            self.server.stop()


def serve(source: BinaryIO, worker: Worker) -> None:
    header = wire.HEADER
    while True:
        head = source.read(header.size)
        if len(head) < header.size:
            return
        kind, link, argument, time_s, length = header.unpack(head)
        payload = source.read(length)
        if len(payload) < length:
            return
        try:
            with worker.lock:
                worker.handle(kind, link, argument, time_s, payload)
                worker.flush_when_due()
        except Exception:  # one record it cannot show must not end the others
            if not worker.failed:
                worker.failed = True
                traceback.print_exc()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--port", type=int, help="the WebSocket server's port (none: no server)")
    parser.add_argument("--standby", action="store_true",
                        help="import everything, say so, then wait for a line {\"port\": N} "
                             "(a spare that replaces a worker that ended at once)")
    args = parser.parse_args()
    if args.standby:
        print(json.dumps({"standby": True}), flush=True)
        line = sys.stdin.buffer.readline()
        if not line:
            return  # the server closed it unused
        args.port = json.loads(line)["port"]
    # Ctrl-C reaches the whole process group, and a service manager's SIGTERM every process
    # of the service: the server closes this process's stdin once it has handed over its
    # last frames, and that ends it, the MCAP files closed (a dead server's pipe ends too)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    worker = Worker(args.port, sys.stdout.buffer)
    threading.Thread(target=worker.flush_periodically, name="mcap-flush", daemon=True).start()
    try:
        serve(sys.stdin.buffer, worker)
    finally:
        with worker.lock:
            worker.close()


if __name__ == "__main__":
    main()
