"""Which reported telemetry fields count as current: the messages each comes from, when each
message last came, and what has been heard since the link came back."""

from __future__ import annotations

import math
from collections.abc import Callable

# The messages each live state field comes from: after a cut, a field is stale until one
# of them arrives again. Home and origin are settings, not live readings: they stay.
SOURCES: dict[str, tuple[str, ...]] = {
    "mode": ("HEARTBEAT", "CURRENT_MODE"),
    "user_mode": ("HEARTBEAT", "CURRENT_MODE"),
    "armed": ("HEARTBEAT",),
    "system_status": ("HEARTBEAT",),
    "landed_state": ("EXTENDED_SYS_STATE",),
    "vtol_state": ("EXTENDED_SYS_STATE",),
    "position_ned": ("LOCAL_POSITION_NED",),
    "velocity_ned": ("LOCAL_POSITION_NED",),
    "global_position": ("GLOBAL_POSITION_INT",),
    "attitude": ("ATTITUDE",),
    "target_ned": ("POSITION_TARGET_LOCAL_NED",),
    "ground_speed_m_s": ("VFR_HUD",),
    "air_speed_m_s": ("VFR_HUD",),
    "climb_rate_m_s": ("VFR_HUD",),
    "heading_deg": ("VFR_HUD", "GLOBAL_POSITION_INT"),
    "actuator_outputs": ("SERVO_OUTPUT_RAW", "ACTUATOR_OUTPUT_STATUS"),
    "ready_to_arm": ("SYS_STATUS",),
    "arming_checks": ("SYS_STATUS",),
    "battery": ("SYS_STATUS", "BATTERY_STATUS"),
    "gps": ("GPS_RAW_INT",),
}


class Freshness:
    """When each message type last came, and since when the readings count as live."""

    def __init__(self, clock: Callable[[], float]) -> None:
        self._clock = clock
        # when each message type last came (the clock's seconds)
        self.received_s: dict[str, float] = {}
        # since when the readings count as live (None: since ever; set when the link
        # comes back); lost while the link is
        self._heard_before: frozenset[str] = frozenset()  # kinds heard before fresh_since_s
        self.fresh_since_s: float | None = None
        self.lost = False

    def ages_at(self, now_s: float) -> dict[str, float]:
        """Seconds since each message type was last received (ms resolution)."""
        return {kind: round(now_s - t, 3) for kind, t in self.received_s.items()}

    def heard_since(self, field: str, since_s: float) -> bool:
        """A message that sets ``field`` came at or after since_s."""
        return any(self.received_s.get(kind, -math.inf) >= since_s for kind in SOURCES[field])

    def stale_fields(self) -> tuple[str, ...]:
        """Live fields not to be taken as current: while the link is lost, every one that
        was reported; after it came back (or rebooted), those reported before and not since."""
        if self.lost:
            return tuple(f for f in SOURCES if any(k in self.received_s for k in SOURCES[f]))
        if self.fresh_since_s is None:
            return ()
        since_s, before = self.fresh_since_s, self._heard_before
        return tuple(
            f for f in SOURCES
            if before.intersection(SOURCES[f]) and not self.heard_since(f, since_s)
        )

    def link_lost(self) -> None:
        self.lost = True

    def link_back(self) -> None:
        self.lost = False
        self._heard_before = frozenset(self.received_s)
        self.fresh_since_s = self._clock()

    def forget_received(self) -> None:
        """A rebooted vehicle: what it reported before stays stale until reported again."""
        self._heard_before = frozenset(self.received_s) | self._heard_before
        self.received_s.clear()
        self.fresh_since_s = self._clock()
