"""Where a link's frames are recorded: its .tlog and its frame taps (Foxglove, MCAP).

Both see the same frames at the same Unix time, in both directions; a signing key
(SETUP_SIGNING) is never recorded, which the link decides before it records."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from pathlib import Path

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.tlog import TlogWriter

# Sees every frame the .tlog records, decoded, on the loop: (message, sent by us, Unix time).
FrameTap = Callable[[mavlink.MAVLink_message, bool, float], None]


class FrameRecord:
    """The .tlog (if any) and the taps, recorded to together."""

    def __init__(self, tlog: TlogWriter | None) -> None:
        self.tlog = tlog
        self._taps: list[FrameTap] = []

    @property
    def active(self) -> bool:
        """Whether a frame is recorded anywhere (else the link need not prepare it)."""
        return self.tlog is not None or bool(self._taps)

    @property
    def tapped(self) -> bool:
        """Whether a tap wants frames decoded."""
        return bool(self._taps)

    @property
    def tlog_path(self) -> Path | None:
        return self.tlog.path if self.tlog is not None else None

    def add_tap(self, tap: FrameTap) -> None:
        self._taps.append(tap)

    def remove_tap(self, tap: FrameTap) -> None:
        with contextlib.suppress(ValueError):
            self._taps.remove(tap)

    def record(
        self, frame: bytes, msg: mavlink.MAVLink_message | None, sent: bool, unix_time_s: float
    ) -> None:
        """One frame, into the .tlog and (decoded, when ``msg`` is given) to every tap."""
        if self.tlog is not None:
            self.tlog.record(frame, unix_time_s)
        if msg is not None:
            for tap in self._taps:
                tap(msg, sent, unix_time_s)

    async def close(self) -> None:
        if self.tlog is not None:
            await self.tlog.close()
        self._taps.clear()  # as the .tlog closes: both have recorded the same frames
