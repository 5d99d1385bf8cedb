"""When a vehicle on a link counts as lost, and when as back.

A vehicle is lost when its HEARTBEAT has been missing for ``heartbeat_timeout_s``, or,
while it streams telemetry (PX4 sends dozens of messages a second on every link), when
nothing at all has come from it for ``silence_timeout_s``: a cut radio shows within about
a second instead of after three missed heartbeats. A vehicle that sends little besides
its heartbeat is judged by the heartbeat alone.

The clock is the event loop's. When the loop itself stalled (the watcher ran late), the
silence it could not observe is not held against the vehicles: a vehicle in the same
process (the simulator) could not have sent anything either.
"""

from __future__ import annotations

from dataclasses import dataclass

# A vehicle sending at least this many frames a second is judged by its silence.
STREAMING_RATE_HZ = 10.0
# The window the rate is measured over.
RATE_WINDOW_S = 1.0
DEFAULT_SILENCE_TIMEOUT_S = 1.0


@dataclass
class _Heard:
    last_frame_s: float
    last_heartbeat_s: float
    window_start_s: float
    window_frames: int = 0
    rate_hz: float = 0.0


class Liveness:
    """Per system id: when it was last heard, at what rate, and whether it is silent."""

    def __init__(self, heartbeat_timeout_s: float, silence_timeout_s: float) -> None:
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.silence_timeout_s = silence_timeout_s
        self._heard: dict[int, _Heard] = {}

    def frame(self, sysid: int, now_s: float) -> None:
        """Any decodable frame from the vehicle's system."""
        heard = self._heard.get(sysid)
        if heard is None:
            return  # not a vehicle (yet): its heartbeat starts the record
        heard.last_frame_s = now_s
        elapsed_s = now_s - heard.window_start_s
        if elapsed_s >= RATE_WINDOW_S:
            heard.rate_hz = heard.window_frames / elapsed_s
            heard.window_start_s = now_s
            heard.window_frames = 0
        heard.window_frames += 1

    def heartbeat(self, sysid: int, now_s: float) -> None:
        heard = self._heard.get(sysid)
        if heard is None:
            self._heard[sysid] = _Heard(now_s, now_s, now_s)
            return
        heard.last_heartbeat_s = now_s

    def back(self, sysid: int, now_s: float) -> None:
        """The vehicle was heard again after a loss: its heartbeat gets a fresh period."""
        heard = self._heard.get(sysid)
        if heard is not None:
            heard.last_heartbeat_s = max(heard.last_heartbeat_s, now_s)

    def known(self, sysid: int) -> bool:
        return sysid in self._heard

    def last_frame_s(self, sysid: int) -> float | None:
        heard = self._heard.get(sysid)
        return None if heard is None else heard.last_frame_s

    def silent_for(self, sysid: int, now_s: float) -> str | None:
        """Why the vehicle counts as lost now ("no HEARTBEAT for 3.0 s", "nothing heard for
        1.0 s"), or None while it is heard."""
        heard = self._heard[sysid]
        if now_s - heard.last_heartbeat_s > self.heartbeat_timeout_s:
            return f"no HEARTBEAT for {self.heartbeat_timeout_s:.1f} s"
        streaming = heard.rate_hz >= STREAMING_RATE_HZ
        bound_s = min(self.silence_timeout_s, self.heartbeat_timeout_s)
        if streaming and now_s - heard.last_frame_s > bound_s:
            return f"nothing heard for {bound_s:.1f} s"
        return None

    def forgive(self, stall_s: float) -> None:
        """The loop stood still for stall_s: nobody could be heard during it."""
        for heard in self._heard.values():
            heard.last_frame_s += stall_s
            heard.last_heartbeat_s += stall_s
