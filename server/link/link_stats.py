"""Per-link traffic statistics: what came in, what went out, what was lost or broken."""

from __future__ import annotations

from dataclasses import dataclass

from .signing import SigningStats

# MAVLink sequence numbers are one byte per sending component.
_SEQ_MODULO = 256


@dataclass(frozen=True)
class LinkStats:
    url: str
    connected: bool  # a vehicle HEARTBEAT arrived within the link's heartbeat timeout
    frames_in: int
    frames_out: int
    bytes_in: int
    bytes_out: int
    lost_frames: int  # sequence gaps, per source system and component
    bad_frames: int  # bad CRC, garbage, truncated frames: counted and dropped
    last_heartbeat_age_s: float | None  # None before the first vehicle HEARTBEAT
    reconnects: int
    signing: SigningStats | None = None  # MAVLink 2 signing: on or off, what was rejected
    # frames of ids outside the dialect, whose checksum cannot be checked: counted, dropped
    unverified_frames: int = 0


class SequenceGapCounter:
    """Counts frames missing from each sender's sequence, as pymavlink's mavutil does.

    A repeated sequence number (a duplicate, e.g. through two routers) is not a loss.
    """

    def __init__(self) -> None:
        self._last_seq: dict[tuple[int, int], int] = {}
        self.lost_frames = 0

    def observe(self, src_system: int, src_component: int, seq: int) -> int:
        """Record one received frame; return how many frames went missing before it."""
        key = (src_system, src_component)
        last = self._last_seq.get(key)
        self._last_seq[key] = seq
        if last is None or seq == last:
            return 0
        missing = (seq - last - 1) % _SEQ_MODULO
        self.lost_frames += missing
        return missing
