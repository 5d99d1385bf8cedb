"""What the sender-fault tests check at the vehicle: the largest gap between two frames of a
kind, the server's sequence, and the modes the vehicle's HEARTBEATs said (from what the
relay in front of it heard: tests/faults/vehicle_apart.py)."""

from __future__ import annotations

import datetime
import itertools
import re
from pathlib import Path

from pymavlink.dialects.v20 import development as mavlink

from server.link.stream.fallback_priority import raised, thread_ids
from tests.faults.sender_relay import Heard
from tests.faults.vehicle_apart import Report

KILL_GAP_S = 0.150
STOP_GAP_S = 0.250  # the stuck watch (150 ms without a beat), then the kill and the handover
OFFBOARD_MODE = 6 << 16  # PX4's custom_mode: main mode in bits 16..23
POSCTL_MODE = 3 << 16
SETPOINT_ID = mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED
STICKS_ID = mavlink.MAVLINK_MSG_ID_MANUAL_CONTROL
GCS_SYSID = 255


def largest_gap(heard: list[Heard], fault_s: float, report: Report,
                sender_log: list[tuple[float, str]]) -> tuple[float, str]:
    """The largest gap between two frames (s), and a failure's account of it: where it lies
    from the fault, what else of the server reached the vehicle meanwhile (every frame kind),
    and the server's sender log lines, each with its time from the fault."""
    a, b = max(itertools.pairwise(h.unix_s for h in heard), key=lambda pair: pair[1] - pair[0])
    inside = [h for h in report.heard if a < h.unix_s < b and h.sysid == GCS_SYSID]
    kinds = sorted({h.msg_id for h in inside})
    lines = [f"{(t - fault_s) * 1000:+.0f} ms {text}" for t, text in sender_log]
    return b - a, (f"from {(a - fault_s) * 1000:+.0f} to {(b - fault_s) * 1000:+.0f} ms of the "
                   f"fault; {len(inside)} other frames of the server in the gap (ids {kinds}); "
                   f"the server's sender log: {lines}")


_ASCTIME = re.compile(r"^(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3}) .*?(setpoint sender.*)$")


def sender_log_lines(log_text: str) -> list[tuple[float, str]]:
    """(unix s, text) of each sender line of a `skyhelm serve` log (asctime, local time)."""
    found = []
    for line in log_text.splitlines():
        match = _ASCTIME.match(line)
        if match:
            when = datetime.datetime.strptime(match.group(1), "%Y-%m-%d %H:%M:%S,%f")
            found.append((when.timestamp(), match.group(2)[:320]))
    return found


def check_sequence(report: Report, since_s: float) -> None:
    """Every frame of the server reached the relay in sequence (no jump back, no gap)."""
    seqs = [h.seq for h in report.heard if h.unix_s >= since_s and h.sysid == GCS_SYSID]
    jumps = [(a, b) for a, b in itertools.pairwise(seqs) if (b - a) % 256 != 1]
    assert jumps == [], f"the sequence jumps at the vehicle: {jumps[:5]}"


def modes_since(report: Report, since_s: float) -> set[int]:
    """The modes of the vehicle's HEARTBEATs (1 Hz) since ``since_s``."""
    modes = [mode for t, mode in report.modes if t >= since_s]
    assert len(modes) >= 2, "too few HEARTBEATs to tell"
    return set(modes)


def raised_threads(pid: int) -> int:
    """How many threads of process ``pid`` run at the sender fallback's real-time priority
    (server.link.stream.fallback_priority)."""
    return sum(map(raised, thread_ids(Path(f"/proc/{pid}/task"))))
