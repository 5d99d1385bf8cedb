"""Per-link traffic statistics: what came in, what went out, what was lost or broken."""

from __future__ import annotations

from server.link.codec.snapshot import LinkStats as LinkStats

# MAVLink sequence numbers are one byte per sending component.
_SEQ_MODULO = 256
# A frame this far behind the newest of its sender is a late one, not a jump ahead.
REORDER_WINDOW = 32


class SequenceGapCounter:
    """Counts frames missing from each sender's sequence, as pymavlink's mavutil does.

    A repeated sequence number (a duplicate, e.g. through two routers) is not a loss, and a
    frame up to REORDER_WINDOW behind the newest is a late one (reordered on the way): it
    was counted missing when a later one overtook it, and is taken back.
    """

    def __init__(self) -> None:
        self._last_seq: dict[tuple[int, int], int] = {}
        self.lost_frames = 0

    def observe(self, src_system: int, src_component: int, seq: int) -> int:
        """Record one received frame; return how many frames went missing before it (-1:
        a late frame, one fewer missing than counted)."""
        key = (src_system, src_component)
        last = self._last_seq.get(key)
        if last is None:
            self._last_seq[key] = seq
            return 0
        ahead = (seq - last) % _SEQ_MODULO
        if ahead == 0:
            return 0
        if ahead > _SEQ_MODULO - REORDER_WINDOW:
            if self.lost_frames == 0:
                return 0
            self.lost_frames -= 1
            return -1
        self._last_seq[key] = seq
        self.lost_frames += ahead - 1
        return ahead - 1
