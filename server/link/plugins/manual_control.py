"""Manual control: the pilot's sticks sent as MANUAL_CONTROL at 25 Hz (QGroundControl's rate).

Sticks that changed go out at once, in place of the streamer's next tick
(``SetpointStreamer.change``); the ticks after it keep their absolute-deadline schedule, so
sticks arriving faster or slower than 25 Hz never change the rate, and a stick moved is
felt without waiting for a tick. Fields as PX4's mavlink_receiver reads them: x pitch
(forward +), y roll (right +), r yaw (clockwise +), each -1000..1000, z throttle 0..1000
(500 = centred: hold altitude in ALTCTL/POSCTL, hover thrust in STABILIZED).

Manual control and the offboard setpoint stream are exclusive: starting one stops the other,
each with an event. Stopping the sticks after they flew is, for PX4, a manual control loss
(after COM_RC_LOSS_T): its NAV_RCL_ACT failsafe applies unless COM_RCL_EXCEPT exempts the mode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from server.link.codec.envelope import SetpointRejected
from server.link.core.state import StreamStats
from server.link.core.vehicle_core import VehicleCore
from server.link.plugins.offboard import Offboard
from server.link.stream.streamer import SetpointStreamer, sender_event

MANUAL_CONTROL_RATE_HZ = 25.0  # QGroundControl's joystick rate
# MANUAL_CONTROL.z is 0..1000; 500 is the centred throttle stick
THROTTLE_CENTRED = 0.5
# each stick's travel: MANUAL_CONTROL's -1000..1000 (z 0..1000) as fractions
_TRAVEL = (("pitch", -1.0, 1.0), ("roll", -1.0, 1.0), ("yaw", -1.0, 1.0), ("throttle", 0.0, 1.0))


@dataclass(frozen=True)
class Sticks:
    """Stick positions: pitch (forward +), roll (right +), yaw (clockwise +) in [-1, 1],
    throttle in [0, 1] (0.5 centred)."""

    pitch: float = 0.0
    roll: float = 0.0
    yaw: float = 0.0
    throttle: float = THROTTLE_CENTRED

    def __post_init__(self) -> None:
        """A stick beyond its travel is refused as a move outside the envelope is: a
        ``SetpointRejected`` naming the stick and the bound it broke."""
        for name, low, high in _TRAVEL:
            value = getattr(self, name)
            if not math.isfinite(value):
                raise SetpointRejected(f"{name} is not a number", field=name)
            if not low <= value <= high:
                raise SetpointRejected(
                    f"{name} {value:g} outside its travel {low:g}..{high:g}",
                    field=name,
                    limit=high if value > high else low,
                )

    def centred(self) -> Sticks:
        """All sticks at rest: hold in POSCTL/ALTCTL, hover thrust in STABILIZED."""
        return Sticks()

    def axes(self) -> tuple[int, int, int, int]:
        """MANUAL_CONTROL (x, y, z, r)."""
        return (
            round(self.pitch * 1000),
            round(self.roll * 1000),
            round(self.throttle * 1000),
            round(self.yaw * 1000),
        )


class ManualControl:
    """The MANUAL_CONTROL stream of one vehicle."""

    def __init__(self, core: VehicleCore, offboard: Offboard) -> None:
        self._core = core
        self._offboard = offboard
        self.streamer = SetpointStreamer(
            core.send, rate_hz=MANUAL_CONTROL_RATE_HZ, channel=core.stream_channel)
        self.streamer.on_sender_change = self._sender_changed
        self.sticks: Sticks | None = None  # what is sent now (None: not sending)
        offboard.on_stream_start(self._stop_for_offboard)

    @property
    def active(self) -> bool:
        return self.streamer.active

    def set_sticks(self, sticks: Sticks) -> Sticks:
        """Send these sticks at once when they changed (in place of the next 25 Hz tick),
        else from the next tick on. Stops the offboard stream first: the two are exclusive."""
        if not self.streamer.active:
            self._offboard.stop_stream("manual control started")
        core = self._core
        x, y, z, r = sticks.axes()
        msg = core.mav.manual_control_encode(core.sysid, x, y, z, r, 0)
        starting = not self.streamer.active
        changed = self.sticks is None or sticks.axes() != self.sticks.axes()
        self.sticks = sticks
        if changed:
            self.streamer.change(msg)
        else:
            self.streamer.update(msg)
        if starting:
            core.publish_event("manual_control", {"active": True, "reason": "sticks"})
        core.hub.notify()
        return sticks

    def centre(self) -> Sticks | None:
        """Keep sending, with every stick at rest (None when not sending)."""
        if self.sticks is None:
            return None
        return self.set_sticks(self.sticks.centred())

    def stop(self, why: str) -> None:
        """Stop sending: PX4 then sees manual control lost after COM_RC_LOSS_T."""
        if self.streamer.active:
            self.streamer.stop()
            self._core.publish_event("manual_control", {"active": False, "reason": why})
            self._core.hub.notify()
        self.sticks = None

    def stats(self) -> StreamStats:
        return self.streamer.stats()

    def _sender_changed(self, change: dict[str, Any]) -> None:
        """The sender process failed (the sticks went on from the thread) or is back."""
        self._core.publish_event("stream", sender_event("sticks", change))
        self._core.hub.notify()

    def _stop_for_offboard(self) -> None:
        self.stop("offboard stream started")
