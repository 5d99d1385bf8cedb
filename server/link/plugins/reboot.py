"""Noticing that a vehicle restarted: its boot clock (``time_boot_ms``) went backwards.

PX4 stamps its telemetry with the milliseconds since it booted. A restarted vehicle with
the same system id starts again near zero, whether the link noticed a loss in between
(a power cycle, a restarted simulator) or not (MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN over a
quick reboot). Messages of different types may arrive slightly out of order, so only a
step back larger than ``BACKWARDS_TOLERANCE_MS`` counts.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from server.link.core.vehicle_core import VehicleCore

# the messages PX4 streams that carry time_boot_ms
_STAMPED = ("ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "SYSTEM_TIME")
BACKWARDS_TOLERANCE_MS = 1000


class RebootWatch:
    """Calls ``on_reboot(reason)`` when the vehicle's boot clock goes backwards.

    Register it before the handlers that keep state, so they see the reset first and the
    message that showed the reboot after it."""

    def __init__(self, core: VehicleCore, on_reboot: Callable[[str], None]) -> None:
        self._on_reboot = on_reboot
        self.latest_boot_ms: int | None = None
        self.reboots = 0
        for kind in _STAMPED:
            core.on_message(kind, self._stamped)

    def _stamped(self, msg: Any) -> None:
        boot_ms = int(msg.time_boot_ms)
        latest = self.latest_boot_ms
        if latest is None or boot_ms > latest:
            self.latest_boot_ms = boot_ms
            return
        if latest - boot_ms <= BACKWARDS_TOLERANCE_MS:
            return  # reordered between message types, or the same instant
        self.latest_boot_ms = boot_ms
        self.reboots += 1
        self._on_reboot(
            f"boot time went back from {latest / 1000.0:.1f} s to {boot_ms / 1000.0:.1f} s"
        )
