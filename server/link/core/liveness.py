"""When a vehicle on a link counts as lost, when as back, and how well it is heard meanwhile.

A vehicle is lost when nothing valid has come from it for a while, never because one
message type went missing: every frame of its autopilot that passed the checksum (and the
signature, with signing on) keeps it alive, the HEARTBEAT no more than any other. PX4 sends
dozens of frames a second on every link, so a vehicle that has been sending at least
STREAMING_RATE_HZ is lost after ``silence_timeout_s`` of silence (a cut radio shows within
about a second; the frames before its first HEARTBEAT count toward that rate, so a link
cut just after the vehicle was discovered shows as soon); a vehicle that sends little
besides its heartbeat is lost after ``heartbeat_timeout_s`` of silence (the MAVLink
heartbeat protocol's 5 s at least, see server.settings). A telemetry radio losing a few
heartbeats in a row is then no verdict.

Before the verdict comes a warning: the link is *degraded* while the vehicle has been silent
for half its bound, while it loses many of its frames on the way (MAVLink sequence gaps, and
what the vehicle says it misses of ours), or while its HEARTBEAT is late although other
frames arrive. ``quality()`` gives the figures and the reasons.

The clock is the event loop's. When the loop itself stalled (the watcher ran late), the
silence it could not observe is not held against the vehicles: a vehicle in the same
process (the simulator) could not have sent anything either.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Literal

from server.link.codec.snapshot import LinkQuality as LinkQuality

# A vehicle sending at least this many frames a second is judged by its silence.
STREAMING_RATE_HZ = 10.0
# The window the rate is measured over.
RATE_WINDOW_S = 1.0
DEFAULT_SILENCE_TIMEOUT_S = 1.0
# The MAVLink heartbeat protocol's timeout: a quiet vehicle is not lost sooner.
MAVLINK_HEARTBEAT_TIMEOUT_S = 5.0
# Silence for this share of the bound is a warning.
SILENCE_WARN_SHARE = 0.5
# The loss figures cover this many seconds, in one-second buckets.
LOSS_WINDOW_S = 5.0
# A loss figure needs this many frames behind it.
LOSS_MIN_FRAMES = 20
# Loss this high (percent) makes the link degraded, and it stays so until below the lower
# figure: a loss hovering at one threshold would otherwise flap the warning.
LOSS_WARN_PCT = 15.0
LOSS_CLEAR_PCT = 10.0
# PX4 sends its HEARTBEAT at 1 Hz: this late, although other frames arrive, is a warning.
HEARTBEAT_WARN_S = 3.0


@dataclass
class _Counts:
    """Frames received and found missing in one bucket of time."""

    start_s: float
    received: int = 0
    lost: int = 0


class _LossWindow:
    """Received and lost counts over the last LOSS_WINDOW_S, in one-second buckets."""

    def __init__(self) -> None:
        self._buckets: deque[_Counts] = deque()

    def add(self, now_s: float, received: int, lost: int) -> None:
        if not self._buckets or now_s - self._buckets[-1].start_s >= 1.0:
            self._buckets.append(_Counts(now_s))
        bucket = self._buckets[-1]
        bucket.received += received
        bucket.lost = max(0, bucket.lost + lost)  # a late frame gives one back

    def pct(self, now_s: float) -> float | None:
        while self._buckets and now_s - self._buckets[0].start_s > LOSS_WINDOW_S:
            self._buckets.popleft()
        received = sum(b.received for b in self._buckets)
        lost = sum(b.lost for b in self._buckets)
        if received + lost < LOSS_MIN_FRAMES:
            return None
        return 100.0 * lost / (received + lost)

    def clear(self) -> None:
        self._buckets.clear()


@dataclass
class _Heard:
    last_frame_s: float
    last_heartbeat_s: float
    window_start_s: float
    window_frames: int = 0
    rate_hz: float = 0.0
    loss_in: _LossWindow = field(default_factory=_LossWindow)
    loss_out: _LossWindow = field(default_factory=_LossWindow)
    # the vehicle's last cumulative (received, lost) counts of our frames
    node_counts: tuple[int, int] | None = None
    degraded: bool = False


class Liveness:
    """Per system id: when it was last heard, at what rate, how lossy, whether it is silent."""

    def __init__(self, heartbeat_timeout_s: float, silence_timeout_s: float) -> None:
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.silence_timeout_s = silence_timeout_s
        self._heard: dict[int, _Heard] = {}
        # sysid -> (first frame s, frames) heard before its first HEARTBEAT: PX4 starts its
        # streams on a link at once, its HEARTBEAT comes within the second, and the frames
        # before it already tell that it streams
        self._before: dict[int, tuple[float, int]] = {}

    def frame(self, sysid: int, now_s: float, missing: int = 0) -> None:
        """Any valid frame from the vehicle's autopilot; ``missing``: frames its sequence
        says went missing before it (-1: it arrived late, after one counted missing)."""
        heard = self._heard.get(sysid)
        if heard is None:  # not a vehicle (yet): its heartbeat starts the record
            first_s, count = self._before.get(sysid, (now_s, 0))
            self._before[sysid] = (first_s, count + 1)
            return
        heard.last_frame_s = now_s
        heard.loss_in.add(now_s, 1, missing)
        elapsed_s = now_s - heard.window_start_s
        if elapsed_s >= RATE_WINDOW_S:
            heard.rate_hz = heard.window_frames / elapsed_s
            heard.window_start_s = now_s
            heard.window_frames = 0
        heard.window_frames += 1

    def heartbeat(self, sysid: int, now_s: float) -> None:
        heard = self._heard.get(sysid)
        if heard is None:
            heard = self._heard[sysid] = _Heard(now_s, now_s, now_s)
            first_s, count = self._before.pop(sysid, (now_s, 0))
            if now_s - first_s >= RATE_WINDOW_S:
                heard.rate_hz = count / (now_s - first_s)
            else:  # the first window began with the first frame
                heard.window_start_s, heard.window_frames = first_s, count
            return
        heard.last_heartbeat_s = now_s

    def node_status(self, sysid: int, now_s: float, received: int, lost: int) -> None:
        """The vehicle's own cumulative count of the frames it received and found missing
        (PX4's LINK_NODE_STATUS: every sender on its link, by sequence numbers)."""
        heard = self._heard.get(sysid)
        if heard is None:
            return
        previous, heard.node_counts = heard.node_counts, (received, lost)
        if previous is None or received < previous[0] or lost < previous[1]:
            heard.loss_out.clear()  # first report, or the vehicle restarted its counts
            return
        heard.loss_out.add(now_s, received - previous[0], lost - previous[1])

    def back(self, sysid: int, now_s: float) -> None:
        """The vehicle was heard again after a loss: its rate and loss start afresh."""
        heard = self._heard.get(sysid)
        if heard is not None:
            heard.window_start_s, heard.window_frames = now_s, 1
            heard.loss_in.clear()
            heard.loss_out.clear()
            heard.node_counts = None

    def known(self, sysid: int) -> bool:
        return sysid in self._heard

    def last_frame_s(self, sysid: int) -> float | None:
        heard = self._heard.get(sysid)
        return None if heard is None else heard.last_frame_s

    def _bound_s(self, heard: _Heard) -> float:
        # the window still being counted already holds a streaming second's frames: a
        # vehicle is judged by its silence from its first second on
        if (heard.rate_hz >= STREAMING_RATE_HZ
                or heard.window_frames >= STREAMING_RATE_HZ * RATE_WINDOW_S):
            return min(self.silence_timeout_s, self.heartbeat_timeout_s)
        return self.heartbeat_timeout_s

    def silent_for(self, sysid: int, now_s: float) -> str | None:
        """Why the vehicle counts as lost now ("nothing heard for 1.0 s"), or None while
        it is heard."""
        heard = self._heard[sysid]
        bound_s = self._bound_s(heard)
        if now_s - heard.last_frame_s > bound_s:
            return f"nothing heard for {bound_s:.1f} s"
        return None

    def quality(self, sysid: int, now_s: float) -> LinkQuality:
        """The vehicle's link figures now, and whether (and why) it is degraded."""
        heard = self._heard[sysid]
        bound_s = self._bound_s(heard)
        silent_s = max(0.0, now_s - heard.last_frame_s)
        heartbeat_age_s = max(0.0, now_s - heard.last_heartbeat_s)
        loss_in = heard.loss_in.pct(now_s)
        loss_out = heard.loss_out.pct(now_s)
        warnings: dict[Literal["silence", "loss_in", "loss_out", "heartbeat"], str] = {}
        silent = silent_s > SILENCE_WARN_SHARE * bound_s
        if silent:
            warnings["silence"] = f"nothing heard for {silent_s:.1f} s (lost at {bound_s:.1f} s)"
        # hysteresis: a degraded link warns of loss down to LOSS_CLEAR_PCT
        loss_warn_pct = LOSS_CLEAR_PCT if heard.degraded else LOSS_WARN_PCT
        if loss_in is not None and loss_in >= loss_warn_pct:
            warnings["loss_in"] = f"{loss_in:.0f} % of the vehicle's frames lost"
        if loss_out is not None and loss_out >= loss_warn_pct:
            warnings["loss_out"] = f"{loss_out:.0f} % of our frames lost on the way to it"
        if heartbeat_age_s > HEARTBEAT_WARN_S and not silent:
            warnings["heartbeat"] = (
                f"no HEARTBEAT for {heartbeat_age_s:.1f} s (other frames arrive)")
        heard.degraded = bool(warnings)
        return LinkQuality(
            silent_s=silent_s, lost_after_s=bound_s, rate_hz=heard.rate_hz,
            loss_in_pct=loss_in, loss_out_pct=loss_out, heartbeat_age_s=heartbeat_age_s,
            degraded=heard.degraded, causes=tuple(warnings), warnings=tuple(warnings.values()),
        )  # fmt: skip

    def forgive(self, stall_s: float) -> None:
        """The loop stood still for stall_s: nobody could be heard during it."""
        for heard in self._heard.values():
            heard.last_frame_s += stall_s
            heard.last_heartbeat_s += stall_s
