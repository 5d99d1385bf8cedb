"""What the vehicle did while the link was down, told once the link is back.

When the link loses the vehicle, the report notes what the operator last saw (mode,
arming, altitude); when it comes back, it waits until the vehicle has reported its mode
and position again and publishes a ``link_restored`` event: "link restored after 5.0 s:
vehicle left OFFBOARD for POSCTL (failsafe), altitude 10.0 -> 9.8 m", with the vehicle's
own texts (STATUSTEXT, decoded EVENTs) that arrived since the loss.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass

from server.link.codec.aio import cancel_and_wait
from server.link.core.vehicle_core import VehicleCore
from server.link.plugins.telemetry import Telemetry

# How long after the link is back the report waits for the fresh mode and position; a
# report is published then in any case, saying what is still unknown.
SETTLE_TIMEOUT_S = 2.0


@dataclass(frozen=True)
class _Seen:
    """What the operator saw of the vehicle at one moment."""

    mode: str
    user_mode: str | None
    armed: bool
    alt_rel_m: float | None
    wall_s: float

    @classmethod
    def of(cls, t: Telemetry, since_s: float | None = None) -> _Seen:
        return cls(t.mode, t.user_mode, t.armed, _alt_rel_m(t, since_s), time.time())


def _alt_rel_m(t: Telemetry, since_s: float | None) -> float | None:
    """Above home, from the global position or else the local one; with since_s, only
    from one reported again since then."""

    def usable(field: str) -> bool:
        return since_s is None or t.heard_since(field, since_s)

    if t.global_position is not None and usable("global_position"):
        return t.global_position.alt_rel_m
    if t.position_ned is not None and usable("position_ned"):
        return -t.position_ned.down_m
    return None


class OutageReport:
    """Notes the state at a loss and reports the difference once the link is back."""

    settle_timeout_s = SETTLE_TIMEOUT_S

    def __init__(self, core: VehicleCore, telemetry: Telemetry) -> None:
        self._core = core
        self._telemetry = telemetry
        self._before: _Seen | None = None
        self._rebooted = False
        self._task: asyncio.Task[None] | None = None
        core.on_connection(self._connection_changed)

    async def close(self) -> None:
        await cancel_and_wait(self._task)

    def vehicle_rebooted(self) -> None:
        self._rebooted = True

    def _connection_changed(self, connected: bool) -> None:
        if not connected:
            if self._before is None:  # a loss during the wait after the last one
                self._before = _Seen.of(self._telemetry)
            self._rebooted = False
            return
        if self._before is None or self._core.lost_s is None:
            return
        if self._task is not None:
            self._task.cancel()
        self._task = asyncio.get_running_loop().create_task(
            self._report(self._before, self._core.lost_s, self._core.now()),
            name=f"outage-report:{self._core.sysid}",
        )

    async def _report(self, before: _Seen, lost_s: float, back_s: float) -> None:
        t = self._telemetry
        since_s = t.fresh_since_s if t.fresh_since_s is not None else back_s

        def settled() -> bool:
            return t.heard_since("mode", since_s) and (
                t.heard_since("global_position", since_s) or t.heard_since("position_ned", since_s)
            )

        await self._core.wait_until(settled, self.settle_timeout_s)
        if not self._core.connected:
            return  # lost again while waiting: the next return reports the whole outage
        self._before = None
        after = _Seen.of(t, since_s)
        texts = [m.text for m in t.statustext if m.time_s >= before.wall_s]
        mode_known = t.heard_since("mode", since_s)
        data: dict[str, object] = {
            "lost_for_s": round(back_s - lost_s, 2),
            "rebooted": self._rebooted,
            "mode_before": before.mode,
            "mode_after": after.mode if mode_known else None,
            "user_mode_after": after.user_mode if mode_known else None,
            "failsafe": mode_known and _failsafe(after),
            "armed_before": before.armed,
            "armed_after": after.armed if mode_known else None,
            "alt_rel_before_m": before.alt_rel_m,
            "alt_rel_after_m": after.alt_rel_m,
            "vehicle_texts": texts,
        }
        data["text"] = _summary(data)
        self._rebooted = False
        self._core.publish_event("link_restored", data)


def _failsafe(after: _Seen) -> bool:
    """PX4 flies a failsafe mode while the user's mode stays what was chosen."""
    return after.user_mode is not None and after.user_mode != after.mode


def _summary(d: dict[str, object]) -> str:
    parts = [f"link restored after {d['lost_for_s']:.1f} s:"]
    if d["rebooted"]:
        parts.append("the vehicle rebooted")
    before, after = d["mode_before"], d["mode_after"]
    if after is None:
        parts.append(f"mode not reported yet (was {before})")
    elif after != before:
        why = " (failsafe)" if d["failsafe"] else ""
        parts.append(f"vehicle left {before} for {after}{why}")
    else:
        parts.append(f"vehicle still in {after}")
    if d["armed_after"] is not None and d["armed_after"] != d["armed_before"]:
        parts.append("it disarmed" if d["armed_before"] else "it armed")
    alt_before, alt_after = d["alt_rel_before_m"], d["alt_rel_after_m"]
    if isinstance(alt_before, float) and isinstance(alt_after, float):
        parts.append(f"altitude {alt_before:.1f} -> {alt_after:.1f} m")
    texts = d["vehicle_texts"]
    if isinstance(texts, list) and texts:
        parts.append("vehicle said: " + " / ".join(str(x).strip() for x in texts))
    return f"{parts[0]} {', '.join(parts[1:])}"
