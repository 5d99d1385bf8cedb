"""Replay of a recorded .tlog as a link transport: ``tlog:PATH?speed=S&loop=1``.

A .tlog holds both directions of a session and does not say which way a frame went, so the
vehicle side is told apart by its source: a frame is replayed when its system announced
itself as a vehicle somewhere in the recording (a HEARTBEAT of an autopilot that is not a
GCS or an onboard controller, the rule Link uses to discover vehicles), unless its own
component announced itself as a GCS. Our own GCS (255/190 by default), other ground
stations and their commands are therefore never fed back as if the vehicle had sent them.

Frames arrive with their recorded spacing divided by ``speed``. Nothing is ever sent:
writes are dropped and counted. At the end of the file the replay stops, so the link's
heartbeat watchdog reports the vehicle lost, unless ``loop`` starts it over.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field
from pathlib import Path

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.aio import cancel_and_wait
from server.link.codec.tlog import iter_tlog
from server.link.codec.urls import LinkUrl
from server.link.transports.base import FrameDecoder, FrameSink, Transport, deliver

log = logging.getLogger(__name__)

MAV_TYPE_GCS = mavlink.MAV_TYPE_GCS
MAV_AUTOPILOT_INVALID = mavlink.MAV_AUTOPILOT_INVALID
_NOT_VEHICLE_TYPES = frozenset({MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER})
# Frames due within this much of each other are delivered together: one timer per batch.
_BATCH_WINDOW_S = 0.002
# A replay running behind still lets the loop breathe every this many frames.
_FRAMES_PER_YIELD = 64


@dataclass(frozen=True)
class _Header:
    system: int
    component: int
    msg_id: int
    payload: bytes


def _header(frame: bytes) -> _Header:
    if frame[0] == mavlink.PROTOCOL_MARKER_V2:
        msg_id = frame[7] | frame[8] << 8 | frame[9] << 16
        return _Header(frame[5], frame[6], msg_id, frame[10 : 10 + frame[1]])
    return _Header(frame[3], frame[4], frame[5], frame[6 : 6 + frame[1]])


def _heartbeat_type_and_autopilot(payload: bytes) -> tuple[int, int]:
    # MAVLink 2 trims trailing zero bytes of a payload: pad back to custom_mode, type, autopilot.
    padded = payload.ljust(6, b"\0")
    return padded[4], padded[5]


@dataclass
class VehicleFrames:
    """The vehicle side of a recording: (unix_time_s, frame) in file order, and what was left."""

    frames: list[tuple[float, bytes]] = field(default_factory=list)
    vehicle_systems: frozenset[int] = frozenset()
    frames_skipped: int = 0


def vehicle_frames(path: Path) -> VehicleFrames:
    """Read a .tlog and keep only the frames the vehicle's systems sent."""
    records = list(iter_tlog(path))
    headers = [_header(frame) for _, frame in records]
    vehicle_systems: set[int] = set()
    gcs_components: set[tuple[int, int]] = set()
    for header in headers:
        if header.msg_id != mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            continue
        mav_type, autopilot = _heartbeat_type_and_autopilot(header.payload)
        if mav_type == MAV_TYPE_GCS:
            gcs_components.add((header.system, header.component))
        elif autopilot != MAV_AUTOPILOT_INVALID and mav_type not in _NOT_VEHICLE_TYPES:
            vehicle_systems.add(header.system)
    kept = [
        record
        for record, header in zip(records, headers, strict=True)
        if header.system in vehicle_systems
        and (header.system, header.component) not in gcs_components
    ]
    return VehicleFrames(kept, frozenset(vehicle_systems), len(records) - len(kept))


class ReplayTransport(Transport):
    """Feeds a recording's vehicle frames to the link on their recorded schedule."""

    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        assert address.path is not None
        self.path = Path(address.path)
        self.speed = address.replay_speed
        self.loop = address.replay_loop
        self.writes_dropped = 0
        self.frames_replayed = 0
        self.frames_skipped = 0
        self.passes_completed = 0
        self._runner: asyncio.Task[None] | None = None

    @property
    def finished(self) -> bool:
        """True once a non-looping replay has delivered its last frame."""
        return self._runner is not None and self._runner.done()

    async def start(self, sink: FrameSink) -> None:
        if not self.path.is_file():
            raise FileNotFoundError(f"no recording at {self.path}")
        recording = await asyncio.to_thread(vehicle_frames, self.path)
        self.frames_skipped = recording.frames_skipped
        if not recording.frames:
            log.warning("%s: no vehicle HEARTBEAT in the recording; nothing to replay", self.path)
        log.info(
            "replaying %s at %g× (%d vehicle frames from system(s) %s, %d others skipped)",
            self.path,
            self.speed,
            len(recording.frames),
            sorted(recording.vehicle_systems),
            recording.frames_skipped,
        )
        self._sink = sink
        self._runner = asyncio.get_running_loop().create_task(
            self._play(sink, recording.frames), name=f"replay:{self.path.name}"
        )

    def write(self, frame: bytes, target_system: int | None) -> bool:
        self.writes_dropped += 1
        return False

    async def close(self) -> None:
        await cancel_and_wait(self._runner)

    async def _play(self, sink: FrameSink, frames: list[tuple[float, bytes]]) -> None:
        if not frames:
            return
        loop = asyncio.get_running_loop()
        first_s = frames[0][0]
        while True:
            # A fresh decoder per pass: the file may end on half a frame's worth of state.
            decoder = FrameDecoder()
            started_s = loop.time()
            since_yield = 0
            for recorded_s, frame in frames:
                delay_s = started_s + (recorded_s - first_s) / self.speed - loop.time()
                if delay_s > _BATCH_WINDOW_S:
                    await asyncio.sleep(delay_s)
                    since_yield = 0
                elif since_yield >= _FRAMES_PER_YIELD:
                    await asyncio.sleep(0)
                    since_yield = 0
                deliver(sink, decoder, frame, None, datagram=False)
                self.frames_replayed += 1
                since_yield += 1
            self.passes_completed += 1
            if not self.loop:
                log.info("replay of %s finished", self.path)
                return
