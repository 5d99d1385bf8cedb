"""A MAVLink connection: transport, codec, statistics, GCS heartbeat, vehicle discovery, tlog.

The link decodes every frame, counts it, records it, and hands it to the vehicle whose
system sent it. Vehicles are discovered from the HEARTBEAT of an autopilot component
(compid 1); they do everything else (commands, state, setpoints) through ``link.send``.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec import px4_messages
from server.link.codec.aio import cancel_and_wait
from server.link.codec.frame_record import FrameRecord, FrameTap
from server.link.codec.signing import MAVLINK_MSG_ID_SETUP_SIGNING, LinkSigning
from server.link.codec.signing_keys import SigningKeyStore
from server.link.codec.tlog import TlogWriter
from server.link.codec.urls import LinkUrl, parse_link_url
from server.link.core.link_stats import LinkStats, SequenceGapCounter
from server.link.core.liveness import (
    DEFAULT_SILENCE_TIMEOUT_S,
    MAVLINK_HEARTBEAT_TIMEOUT_S,
    Liveness,
)
from server.link.roster import MAV_COMP_ID_AUTOPILOT1, VehicleRoster
from server.link.stream.stream_channel import LinkHandover, StreamChannel, decode_sent
from server.link.transports import Peer, Transport, create_transport
from server.link.vehicle import Vehicle

log = logging.getLogger(__name__)

GCS_HEARTBEAT_PERIOD_S = 1.0
# How often silence is looked for: the delay added to the silence bound at most.
HEARTBEAT_CHECK_PERIOD_S = 0.1
# A check later than this was held up by the loop itself (see Liveness.forgive).
LOOP_STALL_S = 0.25
# SETUP_SIGNING's message id as a MAVLink 2 frame carries it (bytes 7..9, little-endian)
_SETUP_SIGNING_ID = MAVLINK_MSG_ID_SETUP_SIGNING.to_bytes(3, "little")

VehicleFactory = Callable[..., Vehicle]
# MAVLink signing link ids, one per link of this process
_signing_link_ids = itertools.count()


class Link:
    """One MAVLink connection and the vehicles seen on it. Create with ``await Link.open(url)``."""

    def __init__(
        self,
        address: LinkUrl,
        transport: Transport,
        *,
        name: str,
        gcs_sysid: int,
        gcs_compid: int,
        tlog: TlogWriter | None,
        heartbeat_timeout_s: float,
        vehicle_factory: VehicleFactory | None,
        silence_timeout_s: float = DEFAULT_SILENCE_TIMEOUT_S,
        signing_store: SigningKeyStore | None = None,
    ) -> None:
        self.name = name
        self.url = address.url
        self.address = address
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.mav = mavlink.MAVLink(None, srcSystem=gcs_sysid, srcComponent=gcs_compid)
        # one signing state for the packer and every decoder (see server.link.codec.signing)
        self.signing = LinkSigning(signing_store, next(_signing_link_ids))
        self.mav.signing = self.signing.state
        transport.codec_factory = self.signing.codec
        self.frames_dropped_out = 0  # frames send() could not write (no peer, not connected)
        # taken once: stats() may be called from other threads (the scene)
        self._loop = asyncio.get_running_loop()
        self._loop_thread = threading.get_ident()
        # send() packs (sequence, signing), writes and counts under this lock: the setpoint
        # sender thread sends too (server.link.stream.stream_thread)
        self._send_lock = threading.Lock()
        self._transport = transport
        # every frame goes out through the setpoint sender process once a stream put this
        # link there (server.link.stream.stream_channel): one sequence, one signing stream
        self._handover = LinkHandover(name, transport, self.mav, self.signing, self._loop,
                                      self._process_sent, self._send_lock)
        self._record = FrameRecord(tlog)
        self._vehicle_factory = vehicle_factory or Vehicle
        self._roster = VehicleRoster(
            name, Liveness(heartbeat_timeout_s, silence_timeout_s), self._make_vehicle)
        self._gaps = SequenceGapCounter()
        self._frames_in = 0
        self._frames_out = 0
        self._bytes_in = 0
        self._bytes_out = 0
        self._bad_frames = 0
        self._unverified_frames = 0
        self._tasks: list[asyncio.Task[None]] = []
        self._closed = False

    @classmethod
    async def open(
        cls,
        url: str,
        *,
        name: str | None = None,
        gcs_sysid: int = 255,
        gcs_compid: int = 190,
        log_dir: Path | None = None,
        heartbeat_timeout_s: float = MAVLINK_HEARTBEAT_TIMEOUT_S,
        silence_timeout_s: float = DEFAULT_SILENCE_TIMEOUT_S,
        vehicle_factory: VehicleFactory | None = None,
        signing_store: SigningKeyStore | None = None,
        on_open: Callable[[Link], None] | None = None,
    ) -> Link:
        """Bind or connect ``url`` (pymavlink style), start the GCS heartbeat and the tlog.

        A ``tcp:`` or serial peer that is not there yet is retried in the background.
        ``vehicle_factory`` replaces the Vehicle class (tests feed links to stand-ins).
        A vehicle is lost after ``silence_timeout_s`` without any valid frame while it
        streams telemetry, after ``heartbeat_timeout_s`` without one otherwise (liveness).
        ``signing_store`` holds the MAVLink signing key (none: the link signs nothing).
        ``on_open(link)`` runs before the first frame is read (to add a frame tap).
        """
        address = parse_link_url(url)
        link_name = name or address.label
        transport = create_transport(address)
        tlog = TlogWriter.in_dir(log_dir, link_name) if log_dir is not None else None
        link = cls(
            address, transport, name=link_name, gcs_sysid=gcs_sysid, gcs_compid=gcs_compid,
            tlog=tlog, heartbeat_timeout_s=heartbeat_timeout_s, vehicle_factory=vehicle_factory,
            silence_timeout_s=silence_timeout_s,
            signing_store=signing_store,
        )
        if on_open is not None:
            on_open(link)
        try:
            await transport.start(_LinkReceiver.of(link))
        except BaseException:
            if tlog is not None:
                await tlog.close()
                tlog.path.unlink(missing_ok=True)  # nothing was recorded
            raise
        link._start_background_tasks()
        log.info("link %s open on %s%s", link_name, url,
                 f", recording {tlog.path}" if tlog is not None else "")
        return link

    async def __aenter__(self) -> Link:
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()

    async def close(self) -> None:
        if self._closed:
            return
        with self._send_lock:
            self._closed = True  # the sender thread's next send is dropped, not written
        await self._handover.close()
        for task in self._tasks:
            await cancel_and_wait(task)
        await self._roster.close()
        await self._transport.close()
        await self.signing.close()
        await self._record.close()
        log.info("link %s closed", self.name)

    @property
    def vehicles(self) -> Mapping[int, Vehicle]:
        return self._roster.vehicles

    @property
    def tlog_path(self) -> Path | None:
        return self._record.tlog_path

    @property
    def local_address(self) -> tuple[str, int] | None:
        """Where this link is bound (host, port): how to learn an ephemeral port."""
        return self._transport.local_address

    def now(self) -> float:
        """Seconds on the event loop's clock, the one the link's heartbeat ages use."""
        return self._loop.time()

    def subscribe_vehicles(self) -> asyncio.Queue[Vehicle]:
        """Vehicles as they are discovered (VehicleRoster.subscribe)."""
        return self._roster.subscribe()

    def unsubscribe_vehicles(self, queue: asyncio.Queue[Vehicle]) -> None:
        self._roster.unsubscribe(queue)

    def add_frame_tap(self, tap: FrameTap) -> None:
        """Call ``tap`` on the loop with every frame the .tlog records (both directions,
        whether or not a .tlog is written). A frame sent from the setpoint sender thread
        reaches it one loop iteration later; the tap must be quick."""
        self._record.add_tap(tap)

    def remove_frame_tap(self, tap: FrameTap) -> None:
        self._record.remove_tap(tap)

    def peer_gone(self, reason: str) -> None:
        """What is at the other end is known to be gone (the server's own simulated
        vehicle's process ended): its vehicles are lost now, for ``reason``."""
        self._roster.lose_all(reason)

    def input_pending(self) -> bool:
        """Frames wait unread on the connection: the loop is behind the vehicle."""
        return self._transport.input_pending()

    def stats(self) -> LinkStats:
        last = self._roster.last_heartbeat_s
        age = None if last is None else max(0.0, self.now() - last)
        return LinkStats(
            url=self.url,
            connected=self._roster.any_connected,
            frames_in=self._frames_in,
            frames_out=self._frames_out,
            bytes_in=self._bytes_in,
            bytes_out=self._bytes_out,
            lost_frames=self._gaps.lost_frames,
            bad_frames=self._bad_frames,
            unverified_frames=self._unverified_frames,
            last_heartbeat_age_s=age,
            reconnects=self._transport.reconnects,
            signing=self.signing.stats(self._roster.vehicles),
        )

    def send(self, msg: mavlink.MAVLink_message) -> None:
        """Pack with this link's sequence and ids (MAVLink 2), write, record. Never blocks:
        a frame the transport cannot take now is dropped and counted. Thread-safe: off the
        loop (the setpoint sender thread) the transport's thread writer writes and the
        tlog record is handed to the loop."""
        target_system = getattr(msg, "target_system", None)
        if self._closed:
            self.frames_dropped_out += 1
            return
        on_loop = threading.get_ident() == self._loop_thread
        while True:
            handed = self._handover.send(msg, target_system)
            if handed is not None:
                self.frames_dropped_out += not handed
                return
            with self._send_lock:
                if self._handover.out is not None:
                    # handed over to the sender process between the look and the lock: the
                    # process numbers frames on from the sequence it was given, so a frame
                    # written here now would repeat a number; it goes through the process
                    continue
                frame = bytes(msg.pack(self.mav))
                self.mav.seq = (self.mav.seq + 1) % 256
                if self._closed or not (
                    self._transport.write(frame, target_system) if on_loop
                    else self._write_off_loop(frame, target_system)
                ):
                    self.frames_dropped_out += 1
                    return
                self._frames_out += 1
                self._bytes_out += len(frame)
                break
        if self._record.active and msg.get_msgId() != MAVLINK_MSG_ID_SETUP_SIGNING:
            if on_loop:
                self._record_sent(msg, frame, time.time())  # a key is never recorded
            else:
                with contextlib.suppress(RuntimeError):  # the loop has closed
                    self._loop.call_soon_threadsafe(self._record_sent, msg, frame, time.time())

    def _record_sent(self, msg: mavlink.MAVLink_message, frame: bytes, unix_time_s: float) -> None:
        self._record.record(frame, msg, True, unix_time_s)

    def stream_channel(self, on_ticks: Callable[[int, list[float]], None]
                       ) -> StreamChannel | None:
        """A stream in the sender process (its ticks reported to ``on_ticks``), or None
        where there is none (TCP, serial, replay; a process that cannot run). The first one
        hands this link's sending over to the process for good."""
        if self._closed:
            return None
        return self._handover.channel(on_ticks)

    def _process_sent(self, records: list[tuple[float, bytes]], dropped: int,
                      _timestamp: int) -> None:
        """What the sender process wrote for this link (on the loop)."""
        self.frames_dropped_out += dropped
        self._frames_out += len(records)
        self._bytes_out += sum(len(frame) for _, frame in records)
        for unix_s, frame in records:  # a key is never recorded; taps get the frame decoded
            if frame[7:10] != _SETUP_SIGNING_ID and self._record.active:
                msg = decode_sent(frame) if self._record.tapped else None
                self._record.record(frame, msg, True, unix_s)

    def _write_off_loop(self, frame: bytes, target_system: int | None) -> bool:
        writer = self._transport.thread_writer()
        if writer is not None:
            return writer(frame, target_system)
        try:  # a transport without one writes on the loop, soon
            self._loop.call_soon_threadsafe(self._transport.write, frame, target_system)
        except RuntimeError:
            return False
        return True

    def send_gcs_heartbeat(self) -> None:
        self.send(self.mav.heartbeat_encode(
            mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE,
        ))

    # -- receiving (called by the transport through _LinkReceiver, on the loop) --

    def _frame_received(self, msg: mavlink.MAVLink_message) -> None:
        if isinstance(msg, mavlink.MAVLink_unknown):
            if not self.signing.accepts_unknown(msg.get_msgbuf()):
                return
            msg = px4_messages.decode_unknown(msg) or msg
        if isinstance(msg, mavlink.MAVLink_unknown):
            # An id outside our dialect: its checksum cannot be checked, so nothing in it
            # (ids, sequence) can be trusted; random bytes often parse as one. Counted and
            # dropped: it is not recorded, discovers nothing and keeps nobody alive.
            self._unverified_frames += 1
            return
        self._frames_in += 1
        src_system = msg.get_srcSystem()
        missing = self._gaps.observe(src_system, msg.get_srcComponent(), msg.get_seq())
        self.signing.note_received(msg)
        if msg.get_msgId() == MAVLINK_MSG_ID_SETUP_SIGNING:
            return  # a key: never recorded, and no vehicle of ours takes one from a peer
        if self._record.active:  # one time for both: a tap's frames match the .tlog's
            self._record.record(msg.get_msgbuf(), msg, False, time.time())
        self._roster.frame_received(msg, missing, self.now())
        vehicle = self._roster.vehicles.get(src_system)
        if vehicle is not None:
            try:
                vehicle.handle_message(msg)
            except Exception:
                # One bad message must not stop the link for every other vehicle.
                log.exception("vehicle %d failed to handle %s", src_system, msg.get_type())

    def _make_vehicle(self, sysid: int, heartbeat: mavlink.MAVLink_message) -> Vehicle:
        return self._vehicle_factory(link=self, sysid=sysid, compid=MAV_COMP_ID_AUTOPILOT1,
                                     heartbeat=heartbeat)

    def _bytes_received(self, count: int) -> None:
        self._bytes_in += count

    def _bad_frames_received(self, count: int) -> None:
        self._bad_frames += count

    def _connection_changed(self, connected: bool) -> None:
        if connected and not self._closed:
            # Introduce ourselves at once so a router or vehicle learns our address.
            self.send_gcs_heartbeat()

    # -- background tasks --

    def _start_background_tasks(self) -> None:
        loop = asyncio.get_running_loop()
        self._tasks = [
            loop.create_task(self._send_gcs_heartbeats(), name=f"gcs-heartbeat:{self.name}"),
            loop.create_task(self._watch_heartbeats(), name=f"heartbeat-watch:{self.name}"),
        ]
        if self._record.tlog is not None:
            self._record.tlog.start()
        self.signing.start()

    async def _send_gcs_heartbeats(self) -> None:
        loop = asyncio.get_running_loop()
        next_s = loop.time()
        while True:
            self.send_gcs_heartbeat()
            next_s += GCS_HEARTBEAT_PERIOD_S
            await asyncio.sleep(max(0.0, next_s - loop.time()))

    async def _watch_heartbeats(self) -> None:
        expected_s = self.now() + HEARTBEAT_CHECK_PERIOD_S
        while True:
            await asyncio.sleep(max(0.0, expected_s - self.now()))
            late_s = self.now() - expected_s
            if late_s > LOOP_STALL_S:
                self._roster.liveness.forgive(late_s)
            expected_s = self.now() + HEARTBEAT_CHECK_PERIOD_S
            self._roster.judge(self.now(), self.input_pending())


@dataclass(frozen=True)
class _LinkReceiver:
    """The link's side of the transport's FrameSink protocol, kept off Link's public surface."""

    frame_received: Callable[[mavlink.MAVLink_message, Peer], None]
    bad_frames_received: Callable[[int], None]
    bytes_received: Callable[[int], None]
    connection_changed: Callable[[bool], None]

    @classmethod
    def of(cls, link: Link) -> _LinkReceiver:
        return cls(lambda msg, _peer: link._frame_received(msg), link._bad_frames_received,
                   link._bytes_received, link._connection_changed)
