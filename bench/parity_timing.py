"""Flight-phase timing and parameters: the simulated vehicle against real PX4 v1.16 SITL.

A plain MAVLink ground station (pymavlink, on the vehicle's onboard link) drives each
vehicle the same way and times every step on the vehicle's own clock (the newest
ATTITUDE.time_boot_ms), so a loaded machine or the sim's ``--speed`` does not move the
figures. Modes are read from CURRENT_MODE and the landed / VTOL state from
EXTENDED_SYS_STATE, both asked at 20 Hz (SET_MESSAGE_INTERVAL), arming from HEARTBEAT and
the "Disarmed" STATUSTEXT.

Quad (a fresh vehicle per run): first HEARTBEAT → HOME_POSITION and → arm accepted;
NAV_TAKEOFF (+5 m) → 4.5 m and → leaves TAKEOFF; climb 1 → 4 m; 10 m north in OFFBOARD →
within 0.5 m; last setpoint → leaves OFFBOARD, the stick-less Position sink rate, stream
resumed → OFFBOARD; NAV_LAND at 5 m → ON_GROUND and → disarmed; RTL from 20 m north and
10 m up → home within 2 m, → ON_GROUND, → disarmed. VTOL: the front and back transition
times. Then the parameter census: every parameter the sim has against PX4 SITL's value for
the same airframe (quad, VTOL, plane; PX4 v1.16 has no SIH rover).

With a PX4 SITL build (``/root/px4sitl``, ``$SKYHELM_PX4_SITL_DIR``) both vehicles fly in
the same run (PX4 instance ``--px4-instance``, default 4, and the next one for the VTOL);
without one, the sim is compared with the PX4 figures recorded in
``bench/px4_reference/parity_timing.json``.

    .venv/bin/python -m bench.parity_timing                  # sim (and PX4 when built)
    .venv/bin/python -m bench.parity_timing --runs 2 --px4   # insist on PX4
    .venv/bin/python -m bench.parity_timing --record-px4     # also rewrite the reference
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import signal
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil

from bench._markdown import table
from bench._report import Section
from bench._results import machine_info, write_results

# the development dialect has CURRENT_MODE (436), which common lacks in this pymavlink
mavutil.set_dialect("development")
M = mavutil.mavlink
REFERENCE = Path(__file__).resolve().parent / "px4_reference" / "parity_timing.json"
DEFAULT_SITL_DIR = Path("/root/px4sitl")
_API_LAYOUT = re.compile(r"API/offboard:\s*PX4 [\d.]+:\((\d+)\+N\)\s*->\s*([\d.]+):\((\d+)\+N\)")
# Every row within this share of PX4's figure.
TOLERANCE = 0.30
# A step that never ends within this much vehicle time fails the run.
STEP_TIMEOUT_S = 120.0
# PX4 custom_mode: main mode in bits 16-23, sub mode in 24-31.
MAIN_POSCTL, MAIN_AUTO, MAIN_OFFBOARD = 3, 4, 6
SUB_TAKEOFF, SUB_LOITER, SUB_RTL, SUB_LAND = 2, 3, 5, 6
LANDED_ON_GROUND = 1
VTOL_FW, VTOL_MC = 4, 3
POSITION_ONLY_MASK = 0b0000_1011_1111_1000  # positions and yaw

QUAD_ROWS: list[tuple[str, str]] = [
    ("home_position_s", "first HEARTBEAT → HOME_POSITION"),
    ("arm_accepted_s", "first HEARTBEAT → arm accepted"),
    ("takeoff_to_4_5_m_s", "NAV_TAKEOFF (+5 m) → 4.5 m"),
    ("takeoff_to_1_m_s", "NAV_TAKEOFF (+5 m) → 1 m"),
    ("takeoff_leaves_s", "NAV_TAKEOFF → leaves TAKEOFF"),
    ("takeoff_leave_alt_m", "height where it leaves TAKEOFF (m)"),
    ("climb_1_to_4_m_s", "climb 1 → 4 m"),
    ("offboard_10_m_s", "10 m north in OFFBOARD → within 0.5 m"),
    ("offboard_loss_s", "last setpoint → leaves OFFBOARD"),
    ("posctl_sink_m_s", "Position without sticks: sink rate (m/s)"),
    ("offboard_resume_s", "stream resumes → OFFBOARD"),
    ("land_on_ground_s", "NAV_LAND at 5 m → ON_GROUND"),
    ("land_disarmed_s", "NAV_LAND → disarmed"),
    ("rtl_home_s", "RTL from 20 m N / 10 m up → home < 2 m"),
    ("rtl_on_ground_s", "RTL → ON_GROUND"),
    ("rtl_disarmed_s", "RTL → disarmed"),
]
VTOL_ROWS: list[tuple[str, str]] = [
    ("vtol_front_transition_s", "VTOL front transition (MC → FW)"),
    ("vtol_back_transition_s", "VTOL back transition (FW → MC)"),
]
# Onboard streams the ground station turns off (both vehicles alike): it reads ATTITUDE
# (the clock), LOCAL_POSITION_NED, HEARTBEAT, CURRENT_MODE, EXTENDED_SYS_STATE, HOME_POSITION.
QUIET_STREAMS = (
    M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, M.MAVLINK_MSG_ID_HIGHRES_IMU,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_ODOMETRY, M.MAVLINK_MSG_ID_ALTITUDE,
    M.MAVLINK_MSG_ID_ATTITUDE_TARGET, M.MAVLINK_MSG_ID_DISTANCE_SENSOR,
    M.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED, M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW,
    M.MAVLINK_MSG_ID_VFR_HUD, M.MAVLINK_MSG_ID_GPS_RAW_INT,
)
# Rows that are no duration, or so short that 30 % is below the clocks' resolution.
SHORT_ROW_SLACK_S = {"home_position_s": 0.25, "offboard_resume_s": 0.15}
# The parameters whose values are per vehicle, not per airframe.
CENSUS_EXEMPT = {"MAV_SYS_ID", "SYS_AUTOSTART"}


class StepFailed(RuntimeError):
    pass


@dataclass
class Gcs:
    """A plain ground station on one vehicle's onboard link, keeping the vehicle's clock."""

    conn: Any
    sysid: int = 0
    clock_s: float = math.nan
    first_heartbeat_s: float = math.nan
    home: Any = None
    home_seen_s: float = math.nan
    main_mode: int = -1
    sub_mode: int = -1
    armed: bool = False
    landed_state: int = 0
    vtol_state: int = 0
    ned_m: list[float] = field(default_factory=lambda: [math.nan] * 3)
    yaw_rad: float = 0.0
    acks: list[tuple[int, int]] = field(default_factory=list)
    texts: list[tuple[float, str]] = field(default_factory=list)
    params: dict[str, float] = field(default_factory=dict)
    param_types: dict[str, int] = field(default_factory=dict)
    param_count: int = -1
    _last_heartbeat_wall: float = -math.inf
    _stream: list[float] | None = None
    _stream_wall: float = -math.inf
    stream_period_s: float = 0.05
    resend_s: float = 0.1

    # -- receiving -------------------------------------------------------------------

    def pump(self, wall_s: float = 0.02) -> None:
        """Take what arrived within wall_s; keep our heartbeat and setpoint stream going."""
        end = time.monotonic() + wall_s
        while True:
            self._keep_alive()
            msg = self.conn.recv_match(blocking=True, timeout=max(end - time.monotonic(), 0.0))
            if msg is None:
                if time.monotonic() >= end:
                    return
                continue
            self._take(msg)

    def _take(self, msg: Any) -> None:
        if msg.get_srcSystem() != self.sysid and self.sysid:
            return
        kind = msg.get_type()
        if kind == "ATTITUDE":
            self.clock_s = msg.time_boot_ms / 1000.0
            self.yaw_rad = msg.yaw
        elif kind == "HEARTBEAT" and msg.get_srcComponent() == 1 and msg.type != M.MAV_TYPE_GCS:
            if not self.sysid:
                self.sysid = msg.get_srcSystem()
            if math.isnan(self.first_heartbeat_s):
                self.first_heartbeat_s = self.clock_s
            self.armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
            self._mode_from(msg.custom_mode)
        elif kind == "CURRENT_MODE":
            self._mode_from(msg.custom_mode)
        elif kind == "HOME_POSITION":
            if self.home is None:
                self.home_seen_s = self.clock_s
            self.home = msg
        elif kind == "EXTENDED_SYS_STATE":
            self.landed_state, self.vtol_state = msg.landed_state, msg.vtol_state
        elif kind == "LOCAL_POSITION_NED":
            self.ned_m = [msg.x, msg.y, msg.z]
        elif kind == "COMMAND_ACK":
            self.acks.append((msg.command, msg.result))
        elif kind == "STATUSTEXT":
            self.texts.append((self.clock_s, msg.text))
            if msg.text.startswith("Disarmed"):
                self.armed = False
        elif kind == "PARAM_VALUE":
            name = msg.param_id.rstrip("\x00")
            self.params[name] = msg.param_value
            self.param_types[name] = msg.param_type
            self.param_count = msg.param_count

    def _mode_from(self, custom_mode: int) -> None:
        self.main_mode = (custom_mode >> 16) & 0xFF
        self.sub_mode = (custom_mode >> 24) & 0xFF

    def _keep_alive(self) -> None:
        now = time.monotonic()
        if now - self._last_heartbeat_wall >= 1.0:
            self._last_heartbeat_wall = now
            self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        if self._stream is not None and now - self._stream_wall >= self.stream_period_s:
            self._stream_wall = now
            north, east, down = self._stream
            self.conn.mav.set_position_target_local_ned_send(
                0, self.sysid, 1, M.MAV_FRAME_LOCAL_NED, POSITION_ONLY_MASK,
                north, east, down, 0, 0, 0, 0, 0, 0, self._stream_yaw, 0)

    # -- waiting, on the vehicle's clock ---------------------------------------------

    def until(
        self, what: str, done: Callable[[], bool], timeout_s: float = STEP_TIMEOUT_S
    ) -> float:
        """The vehicle clock at which `done` first holds."""
        start = self.clock_s
        wall_end = time.monotonic() + timeout_s * 4 + 30.0
        while not done():
            self.pump()
            late = not math.isnan(start) and self.clock_s - start > timeout_s
            if late or time.monotonic() > wall_end:
                raise StepFailed(f"{what}: not within {timeout_s} s (vehicle clock)")
        return self.clock_s

    def hold_for(self, seconds: float) -> None:
        start = self.clock_s
        self.until(f"{seconds} s", lambda: self.clock_s - start >= seconds, seconds + 5)

    # -- sending ---------------------------------------------------------------------

    def command(self, command: int, *params: float) -> None:
        p = [*params, *[0.0] * (7 - len(params))]
        self.conn.mav.command_long_send(self.sysid, 1, command, 0, *p)

    def command_accepted(self, what: str, command: int, *params: float) -> float:
        """Send until ACCEPTED (PX4's DO_SET_MODE acks twice: the last ack counts)."""
        sent_wall = -math.inf
        while True:
            if time.monotonic() - sent_wall > self.resend_s:
                self.acks.clear()
                self.command(command, *params)
                sent_wall = time.monotonic()
            self.pump(0.01)
            results = [r for c, r in self.acks if c == command]
            if results and results[-1] == M.MAV_RESULT_ACCEPTED:
                return self.clock_s
            if not math.isnan(self.clock_s) and self.clock_s > STEP_TIMEOUT_S * 3:
                raise StepFailed(f"{what}: never accepted ({results})")

    def set_mode(self, main: int, sub: int = 0) -> None:
        self.command_accepted(f"mode {main}/{sub}", M.MAV_CMD_DO_SET_MODE,
                              M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub)
        self.until(f"in mode {main}/{sub}", lambda: self.in_mode(main, sub), 5.0)

    def in_mode(self, main: int, sub: int = 0) -> bool:
        return self.main_mode == main and (main != MAIN_AUTO or self.sub_mode == sub)

    def ask_interval(self, msg_id: int, hz: float) -> None:
        self.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)

    def drain(self) -> None:
        """Take everything already received, so the clock is the vehicle's latest."""
        while (msg := self.conn.recv_match(blocking=False)) is not None:
            self._take(msg)

    def stream(self, ned_m: list[float] | None) -> None:
        """Stream a position setpoint (None: stop streaming)."""
        self.drain()
        self._stream = None if ned_m is None else list(ned_m)
        self._stream_yaw = self.yaw_rad
        self._stream_wall = -math.inf

    # -- geometry ---------------------------------------------------------------------

    def height_m(self) -> float:
        return self.home.z - self.ned_m[2] if self.home is not None else math.nan

    def home_ned_m(self) -> list[float]:
        return [self.home.x, self.home.y, self.home.z]

    def distance_m(self, target: Sequence[float], horizontal: bool = False) -> float:
        axes = 2 if horizontal else 3
        return math.sqrt(sum((self.ned_m[i] - target[i]) ** 2 for i in range(axes)))


# -- the flights --------------------------------------------------------------------


def boot(gcs: Gcs) -> dict[str, float]:
    """First HEARTBEAT, HOME_POSITION (as streamed by default), first accepted arm."""
    gcs.until("first HEARTBEAT", lambda: not math.isnan(gcs.first_heartbeat_s)
              and not math.isnan(gcs.clock_s), 60.0)
    if math.isnan(gcs.first_heartbeat_s):
        gcs.first_heartbeat_s = gcs.clock_s
    gcs.until("HOME_POSITION", lambda: gcs.home is not None, 30.0)
    row = {"home_position_s": gcs.home_seen_s - gcs.first_heartbeat_s}
    for msg_id in (M.MAVLINK_MSG_ID_CURRENT_MODE, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE):
        gcs.ask_interval(msg_id, 20.0)
    # what the timing does not read, off: a ground station that falls behind the stream
    # (over 1000 messages a second at --speed 3) would read a stale clock
    for msg_id in QUIET_STREAMS:
        gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, -1)
        gcs.pump(0.01)
    armed_s = gcs.command_accepted("arm", M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    row["arm_accepted_s"] = armed_s - gcs.first_heartbeat_s
    return row


def takeoff(gcs: Gcs, height_m: float) -> dict[str, float]:
    """NAV_TAKEOFF to height_m above home, armed on the ground: times to 1 m, 4.5 m (of 5),
    the end of TAKEOFF and the height there."""
    target_amsl_m = gcs.home.altitude / 1000.0 + height_m
    sent_s = gcs.command_accepted("takeoff", M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan,
                                  math.nan, math.nan, target_amsl_m)
    one_m_s = gcs.until("1 m", lambda: gcs.height_m() >= 1.0)
    four_m_s = gcs.until("4 m", lambda: gcs.height_m() >= min(4.0, height_m - 1.0))
    near_s = gcs.until("0.5 m below", lambda: gcs.height_m() >= height_m - 0.5)
    left_s = gcs.until("leaves TAKEOFF", lambda: not gcs.in_mode(MAIN_AUTO, SUB_TAKEOFF))
    return {
        "takeoff_to_1_m_s": one_m_s - sent_s,
        "takeoff_to_4_5_m_s": near_s - sent_s,
        "climb_1_to_4_m_s": four_m_s - one_m_s,
        "takeoff_leaves_s": left_s - sent_s,
        "takeoff_leave_alt_m": gcs.height_m(),
    }


def offboard_to(gcs: Gcs, target: list[float], radius_m: float = 0.5) -> float:
    """Fly to target in OFFBOARD (switching to it first if needed): time to within radius_m."""
    if not gcs.in_mode(MAIN_OFFBOARD):
        gcs.stream(list(gcs.ned_m))
        gcs.hold_for(1.0)
        gcs.set_mode(MAIN_OFFBOARD)
        gcs.hold_for(1.0)
    gcs.stream(target)
    start = gcs.clock_s
    return gcs.until("offboard target", lambda: gcs.distance_m(target) <= radius_m) - start


def offboard_loss(gcs: Gcs) -> dict[str, float]:
    """Stop the stream: time to leave OFFBOARD, the stick-less sink, the return."""
    gcs.stream(None)
    stopped_s = gcs.clock_s
    left_s = gcs.until("leaves OFFBOARD", lambda: not gcs.in_mode(MAIN_OFFBOARD), 10.0)
    gcs.hold_for(0.5)
    z0, t0 = gcs.ned_m[2], gcs.clock_s
    gcs.hold_for(2.0)
    sink = (gcs.ned_m[2] - z0) / (gcs.clock_s - t0)
    gcs.stream(list(gcs.ned_m))
    resumed_s = gcs.clock_s
    back_s = gcs.until("back in OFFBOARD", lambda: gcs.in_mode(MAIN_OFFBOARD), 10.0)
    return {"offboard_loss_s": left_s - stopped_s, "posctl_sink_m_s": sink,
            "offboard_resume_s": back_s - resumed_s}


def land_here(gcs: Gcs, prefix: str, command: int, home_radius: bool = False) -> dict[str, float]:
    """NAV_LAND or RTL: times to home within 2 m (RTL), ON_GROUND, disarmed."""
    sent_s = gcs.command_accepted(prefix, command)
    gcs.stream(None)
    row: dict[str, float] = {}
    if home_radius:
        home = gcs.home_ned_m()
        row[f"{prefix}_home_s"] = gcs.until(
            "home within 2 m", lambda: gcs.distance_m(home, horizontal=True) < 2.0) - sent_s
    row[f"{prefix}_on_ground_s"] = gcs.until(
        "ON_GROUND", lambda: gcs.landed_state == LANDED_ON_GROUND, 150.0) - sent_s
    row[f"{prefix}_disarmed_s"] = gcs.until("disarmed", lambda: not gcs.armed, 30.0) - sent_s
    return row


def fly_quad(gcs: Gcs) -> dict[str, float]:
    row = boot(gcs)
    row.update(takeoff(gcs, 5.0))
    gcs.hold_for(1.0)
    start = list(gcs.ned_m)
    row["offboard_10_m_s"] = offboard_to(gcs, [start[0] + 10.0, start[1], start[2]])
    gcs.hold_for(1.0)
    row.update(offboard_loss(gcs))
    home = gcs.home_ned_m()
    offboard_to(gcs, [gcs.ned_m[0], gcs.ned_m[1], home[2] - 5.0], 0.15)
    gcs.hold_for(1.5)
    row.update(land_here(gcs, "land", M.MAV_CMD_NAV_LAND))
    # second flight: RTL from 20 m north, 10 m up
    gcs.set_mode(MAIN_AUTO, SUB_LOITER)
    gcs.command_accepted("arm", M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    takeoff(gcs, 10.0)
    home = gcs.home_ned_m()
    offboard_to(gcs, [home[0] + 20.0, home[1], home[2] - 10.0])
    gcs.hold_for(1.5)
    row.update(land_here(gcs, "rtl", M.MAV_CMD_NAV_RETURN_TO_LAUNCH, home_radius=True))
    return row


def fly_vtol(gcs: Gcs) -> dict[str, float]:
    boot(gcs)
    takeoff(gcs, 20.0)
    gcs.hold_for(1.0)
    sent_s = gcs.command_accepted("front transition", M.MAV_CMD_DO_VTOL_TRANSITION, VTOL_FW)
    front = gcs.until("FW", lambda: gcs.vtol_state == VTOL_FW, 30.0) - sent_s
    gcs.hold_for(6.0)
    sent_s = gcs.command_accepted("back transition", M.MAV_CMD_DO_VTOL_TRANSITION, VTOL_MC)
    back = gcs.until("MC", lambda: gcs.vtol_state == VTOL_MC, 30.0) - sent_s
    return {"vtol_front_transition_s": front, "vtol_back_transition_s": back}


def read_params(gcs: Gcs) -> dict[str, float | int]:
    """PARAM_REQUEST_LIST, then the missing indices one by one; values decoded by type."""
    gcs.params.clear()
    gcs.conn.mav.param_request_list_send(gcs.sysid, 1)
    quiet_wall = time.monotonic()
    seen = 0
    while time.monotonic() - quiet_wall < 3.0:
        gcs.pump(0.1)
        if len(gcs.params) != seen:
            seen, quiet_wall = len(gcs.params), time.monotonic()
        if gcs.param_count > 0 and len(gcs.params) >= gcs.param_count:
            break
    return {name: _decode(value, gcs.param_types[name]) for name, value in gcs.params.items()}


def _decode(wire: float, param_type: int) -> float | int:
    import struct

    if param_type in (M.MAV_PARAM_TYPE_INT32, M.MAV_PARAM_TYPE_UINT8, M.MAV_PARAM_TYPE_INT8,
                      M.MAV_PARAM_TYPE_INT16, M.MAV_PARAM_TYPE_UINT16, M.MAV_PARAM_TYPE_UINT32):
        return int(struct.unpack("<i", struct.pack("<f", wire))[0])
    return round(float(wire), 6)


# -- the vehicles -------------------------------------------------------------------


@contextlib.contextmanager
def sim_vehicle(airframe: str, speed: float) -> Iterator[Gcs]:
    """``python -m sim`` sending its onboard link to our ephemeral port."""
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255, dialect="development")
    port = conn.port.getsockname()[1]
    proc = subprocess.Popen(
        [sys.executable, "-m", "sim", "--airframe", airframe, "--speed", str(speed),
         "--api-port", str(port), "--api-local-port", "0", "--gcs-port", "0",
         "--gcs-local-port", "0", "--exit-on-stdin-eof"],
        stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    gcs = Gcs(conn, stream_period_s=0.05 / max(speed, 1.0), resend_s=0.1 / max(speed, 1.0))
    try:
        yield gcs
    finally:
        _end(proc)
        conn.close()


def _end(proc: subprocess.Popen[bytes]) -> None:
    if proc.stdin is not None:
        proc.stdin.close()
    proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def px4_sitl_dir() -> Path | None:
    root = Path(os.environ.get("SKYHELM_PX4_SITL_DIR") or DEFAULT_SITL_DIR)
    built = (root / "build" / "px4_sitl_default" / "bin" / "px4").is_file()
    return root if built and (root / "run.sh").is_file() else None


@contextlib.contextmanager
def px4_vehicle(root: Path, instance: int, model: str) -> Iterator[Gcs]:
    """A fresh PX4 SITL instance (clean parameters) through the kit's run.sh."""
    layout = _API_LAYOUT.search((root / "run.sh").read_text())
    if layout is None:
        raise RuntimeError(f"{root / 'run.sh'} does not document its API port layout")
    _px4_base, host, client_base = layout.groups()
    conn = mavutil.mavlink_connection(f"udpin:{host}:{int(client_base) + instance}",
                                      source_system=255, dialect="development")
    subprocess.run([str(root / "stop.sh"), str(instance)], capture_output=True, timeout=30)
    started = subprocess.run([str(root / "run.sh"), str(instance), model],
                             env={**os.environ, "PX4_CLEAN": "1"},
                             capture_output=True, text=True, timeout=90)
    if started.returncode != 0:
        raise RuntimeError(f"run.sh failed: {started.stdout}{started.stderr}")
    pid = int(started.stdout.strip().splitlines()[-1])
    try:
        yield Gcs(conn, sysid=instance + 1)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
        for _ in range(100):
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.1)
        else:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        conn.close()


# -- the run ------------------------------------------------------------------------


def _medians(runs: list[dict[str, float]]) -> dict[str, float]:
    keys = {k for run in runs for k in run}
    return {k: statistics.median(run[k] for run in runs if k in run) for k in sorted(keys)}


def measure(vehicles: Callable[[str], contextlib.AbstractContextManager[Gcs]],
            runs: int) -> dict[str, Any]:
    quad_runs: list[dict[str, float]] = []
    for _ in range(runs):
        with vehicles("quad") as gcs:
            quad_runs.append(fly_quad(gcs))
    params: dict[str, dict[str, float | int]] = {}
    for airframe in ("quad", "plane"):
        with vehicles(airframe) as gcs:
            gcs.until("first HEARTBEAT", lambda: not math.isnan(gcs.first_heartbeat_s), 60.0)
            gcs.hold_for(2.0)
            params[airframe] = read_params(gcs)
    vtol_runs: list[dict[str, float]] = []
    for _ in range(runs):
        with vehicles("vtol") as gcs:
            vtol_runs.append(fly_vtol(gcs))
            params["vtol"] = read_params(gcs)
    return {"quad_runs": quad_runs, "vtol_runs": vtol_runs,
            "medians": {**_medians(quad_runs), **_medians(vtol_runs)}, "params": params}


def compare(sim: dict[str, float], px4: dict[str, float]) -> list[dict[str, Any]]:
    rows = []
    for key, label in QUAD_ROWS + VTOL_ROWS:
        ours, theirs = sim.get(key, math.nan), px4.get(key, math.nan)
        ratio = ours / theirs if theirs else math.nan
        slack = SHORT_ROW_SLACK_S.get(key, 0.0)
        within = abs(ours - theirs) <= max(TOLERANCE * abs(theirs), slack)
        rows.append({"key": key, "step": label, "sim": ours, "px4": theirs,
                     "ratio": ratio, "within_30_pct": bool(within)})
    return rows


def census(sim: dict[str, dict[str, float | int]],
           px4: dict[str, dict[str, float | int]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for airframe, ours in sim.items():
        theirs = px4.get(airframe, {})
        shared = sorted(set(ours) & set(theirs))
        differ = {n: [ours[n], theirs[n]] for n in shared
                  if n not in CENSUS_EXEMPT and not _same(ours[n], theirs[n])}
        out[airframe] = {"sim_count": len(ours), "px4_count": len(theirs),
                         "shared": len(shared), "differ": differ,
                         "sim_only": sorted(set(ours) - set(theirs)) if theirs else []}
    return out


def _same(a: float | int, b: float | int) -> bool:
    return math.isclose(float(a), float(b), rel_tol=1e-5, abs_tol=1e-6)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2, help="flights per vehicle (median)")
    parser.add_argument("--speed", type=float, default=3.0, help="the sim's --speed")
    parser.add_argument("--px4", action="store_true", help="fail without a PX4 SITL build")
    parser.add_argument("--no-px4", action="store_true", help="the sim alone")
    parser.add_argument("--px4-instance", type=int, default=4,
                        help="PX4 SITL instance (the VTOL flies on the same one)")
    parser.add_argument("--record-px4", action="store_true",
                        help=f"write PX4's figures to {REFERENCE.name}")
    args = parser.parse_args(argv)
    load_before = os.getloadavg()
    root = None if args.no_px4 else px4_sitl_dir()
    if args.px4 and root is None:
        print("no PX4 SITL build", file=sys.stderr)
        return 1
    models = {"quad": "sihsim_quadx", "vtol": "sihsim_standard_vtol",
              "plane": "sihsim_airplane"}
    sim = measure(lambda airframe: sim_vehicle(airframe, args.speed), args.runs)
    if root is not None:
        instance = args.px4_instance
        px4 = measure(lambda airframe: px4_vehicle(root, instance, models[airframe]), args.runs)
        source = f"PX4 v1.16 SITL measured in this run (instance {instance})"
        if args.record_px4:
            REFERENCE.parent.mkdir(parents=True, exist_ok=True)
            REFERENCE.write_text(json.dumps(
                {"measured": time.strftime("%Y-%m-%d"), "models": models, **px4},
                indent=1, sort_keys=True) + "\n")
    else:
        px4 = json.loads(REFERENCE.read_text())
        source = f"PX4 v1.16 SITL figures recorded {px4.get('measured', '?')} ({REFERENCE.name})"
    rows = compare(sim["medians"], px4["medians"])
    params = census(sim["params"], px4.get("params", {}))
    result = {
        "px4_source": source, "runs": args.runs, "sim_speed": args.speed,
        "rows": rows, "all_within_30_pct": all(r["within_30_pct"] for r in rows),
        "census": params, "sim": sim, "px4_medians": px4["medians"],
        "machine": machine_info(load_before),
    }
    print(f"{'step':44} {'sim':>8} {'PX4':>8} {'sim/PX4':>8}")
    for r in rows:
        flag = "" if r["within_30_pct"] else "  OUT"
        print(f"{r['step']:44} {r['sim']:8.2f} {r['px4']:8.2f} {r['ratio']:8.2f}{flag}")
    print(f"({source}; medians of {args.runs}; sim at --speed {args.speed})")
    for airframe, c in params.items():
        print(f"parameters {airframe}: sim {c['sim_count']}, PX4 {c['px4_count']}, "
              f"shared {c['shared']}, differing {len(c['differ'])}: {c['differ']}")
    write_results("parity_timing", result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


def report(result: dict[str, Any]) -> Section | None:
    rows = [[r["step"], f"{r['sim']:.2f}", f"{r['px4']:.2f}", f"{r['ratio']:.2f}",
             "yes" if r["within_30_pct"] else "**no**"] for r in result["rows"]]
    census_rows = [[a, c["sim_count"], c["px4_count"], c["shared"], len(c["differ"])]
                   for a, c in result["census"].items()]
    markdown = (
        f"Each step on the vehicle's own clock, medians of {result['runs']} runs; "
        f"{result['px4_source']}.\n\n"
        + table(["step", "sim", "PX4", "sim / PX4", "within 30 %"], rows)
        + "\n\nParameters (system id and SYS_AUTOSTART aside):\n\n"
        + table(["airframe", "sim", "PX4", "shared", "differing"], census_rows)
    )
    return Section("Flight-phase timing: sim vs PX4 SITL", 80, markdown)
