"""MAVLink telemetry logs (.tlog): the format pymavlink, MAVProxy and QGroundControl read.

Each frame is stored as an 8-byte big-endian Unix timestamp in microseconds followed by
the raw frame bytes, both directions in one file. Frames are buffered in memory and
written by a timer at least every ``flush_interval_s``, so recording costs the event loop
one small write per second instead of one per frame; a full buffer is written at once.
"""

from __future__ import annotations

import asyncio
import re
import struct
import time
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import BinaryIO

from server.link.codec.aio import cancel_and_wait

_TIMESTAMP = struct.Struct(">Q")
_UNSAFE_NAME_CHARS = re.compile(r"[^A-Za-z0-9._-]+")
DEFAULT_FLUSH_INTERVAL_S = 1.0
DEFAULT_MAX_BUFFER_BYTES = 1 << 20


def tlog_path(log_dir: Path, link_name: str, started: datetime | None = None) -> Path:
    """``<log_dir>/<UTC time>-<link name>.tlog``; a name already taken gets a counter."""
    stamp = (started or datetime.now(UTC)).astimezone(UTC).strftime("%Y%m%dT%H%M%SZ")
    safe_name = _UNSAFE_NAME_CHARS.sub("_", link_name).strip("_") or "link"
    candidate = log_dir / f"{stamp}-{safe_name}.tlog"
    counter = 1
    while candidate.exists():
        candidate = log_dir / f"{stamp}-{safe_name}-{counter}.tlog"
        counter += 1
    return candidate


class TlogWriter:
    """Records frames to one .tlog file; :meth:`start` (on the loop) flushes on a timer."""

    def __init__(
        self,
        path: Path,
        *,
        flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S,
        max_buffer_bytes: int = DEFAULT_MAX_BUFFER_BYTES,
    ) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self.flush_interval_s = flush_interval_s
        self.max_buffer_bytes = max_buffer_bytes
        self.frames_recorded = 0
        self._file: BinaryIO | None = path.open("xb")
        self._buffer = bytearray()
        self._flusher: asyncio.Task[None] | None = None

    @classmethod
    def in_dir(cls, log_dir: Path, link_name: str) -> TlogWriter:
        return cls(tlog_path(log_dir, link_name))

    def start(self) -> None:
        if self._flusher is None and self._file is not None:
            self._flusher = asyncio.get_running_loop().create_task(
                self._flush_periodically(), name=f"tlog-flush:{self.path.name}"
            )

    def record(self, frame: bytes | bytearray, unix_time_s: float | None = None) -> None:
        if self._file is None:
            return
        stamp_us = int((time.time() if unix_time_s is None else unix_time_s) * 1e6)
        self._buffer += _TIMESTAMP.pack(stamp_us)
        self._buffer += frame
        self.frames_recorded += 1
        if len(self._buffer) >= self.max_buffer_bytes:
            self.flush()

    def flush(self) -> None:
        if self._file is None or not self._buffer:
            return
        self._file.write(self._buffer)
        self._file.flush()
        self._buffer.clear()

    async def close(self) -> None:
        await cancel_and_wait(self._flusher)
        self._flusher = None
        self.flush()
        if self._file is not None:
            self._file.close()
            self._file = None

    async def _flush_periodically(self) -> None:
        while True:
            await asyncio.sleep(self.flush_interval_s)
            self.flush()


def iter_tlog(path: Path) -> Iterator[tuple[float, bytes]]:
    """Yield (unix_time_s, frame bytes) from a .tlog, e.g. to replay a session.

    Frame boundaries come from the MAVLink header (v1 or v2, signed or not); a truncated
    final record (a crash mid-write) ends the iteration.
    """
    data = path.read_bytes()
    offset = 0
    while offset + _TIMESTAMP.size + 2 <= len(data):
        (stamp_us,) = _TIMESTAMP.unpack_from(data, offset)
        start = offset + _TIMESTAMP.size
        length = _frame_length(data, start)
        if length is None or start + length > len(data):
            return
        yield stamp_us / 1e6, data[start : start + length]
        offset = start + length


def _frame_length(data: bytes, start: int) -> int | None:
    magic = data[start]
    payload_len = data[start + 1]
    if magic == 0xFE:  # MAVLink 1: 6-byte header + payload + 2-byte CRC
        return 6 + payload_len + 2
    if magic == 0xFD:  # MAVLink 2: 10-byte header + payload + CRC (+ 13-byte signature)
        if start + 2 >= len(data):
            return None
        signed = data[start + 2] & 0x01
        return 10 + payload_len + 2 + (13 if signed else 0)
    return None
