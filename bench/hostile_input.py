"""Hostile input on both ends of a flight: malformed MAVLink into the server's link port and
into the simulated vehicle's port while the server streams offboard setpoints to it.

Topology as with PX4 SITL: the server's link listens (udpin) on a loopback port, the
simulated vehicle sends there from its own port (a configured remote port). A stranger's
socket sends, as fast as the receivers take them, datagrams of six kinds:

- garbage: random bytes without a MAVLink start marker
- unknown_id: a MAVLink 2 header of an id outside the dialect, random payload and checksum
  (pymavlink hands these over as UNKNOWN_<id>: the frames that used to hijack the sim)
- truncated: a good frame cut short
- wrong_crc: a good frame with its checksum spoiled
- oversized: a 255-byte payload with a bad checksum followed by up to 8 KB of junk
- absurd: good frames (checksum holds) with absurd field values (NaN, inf, extreme
  integers). To the server they claim the vehicle's system id from the stranger's address;
  to the sim they come from a stranger system and target another vehicle (except
  parameter reads and TIMESYNC, which the sim answers).

Each kind has one known outcome per receiver, so the counters must match what was sent.
Meanwhile the stream's arrival at the vehicle is timed (largest gap), the vehicle must stay
in OFFBOARD (its offboard-loss failsafe would show a stall), the sim must keep sending to
the server, and arm/disarm must work after the flood.

    python -m bench.hostile_input [--frames N]   # N per end, default 30000 (long run: 100000)

prints the figures and writes bench/results/hostile_input.json. tests/faults/
test_hostile_input.py runs the same with a share of the frames.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import math
import os
import random
import socket
import struct
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from bench._markdown import ratio, table
from bench._report import Section
from bench._results import machine_info, write_results
from server.link import Link, Vehicle
from sim.process.runner import SimCluster

LOOPBACK = "127.0.0.1"
VEHICLE_SYSID = 1
STRANGER_SYSID = 77
OTHER_VEHICLE_SYSID = 200
KINDS = ("garbage", "unknown_id", "truncated", "wrong_crc", "oversized", "absurd")
# Per datagram: (bad frames, unverified frames, taken messages) at each receiver.
SERVER_OUTCOME = {
    "garbage": (1, 0, 0), "unknown_id": (0, 1, 0), "truncated": (1, 0, 0),
    "wrong_crc": (1, 0, 0), "oversized": (2, 0, 0),
    "absurd": (1, 0, 0),  # claims a system heard from another address: dropped
}  # fmt: skip
SIM_OUTCOME = {
    "garbage": (1, 0, 0), "unknown_id": (0, 1, 0), "truncated": (1, 0, 0),
    "wrong_crc": (1, 0, 0), "oversized": (2, 0, 0), "absurd": (0, 0, 1),
}  # fmt: skip
# Datagrams in flight before the sender waits for the receivers to catch up: well within
# a loopback socket's receive buffer, so the kernel drops none and the counts are exact.
WINDOW_DATAGRAMS = 16
WINDOW_BYTES = 24_000
STREAM_RATE_HZ = 50.0
# ~1 minute on a 2-core machine, within `make bench`'s budget; --frames 100000 for the long run
DEFAULT_FRAMES = 30_000
LONG_FRAMES = 100_000
_MARKERS = (mavlink.PROTOCOL_MARKER_V1, mavlink.PROTOCOL_MARKER_V2)
_ABSURD_FLOATS = (math.nan, math.inf, -math.inf, 3.4e38, -3.4e38, 1e-45, 0.0)
_PARAM_CHARS = "ABCDEFGHIJKLMNOPQRSTUVWXYZ_0123456789"
_UNKNOWN_IDS_TAKEN = frozenset({8, 300, 380, 395, 397, 410, 411, 412, 413})


def _no_markers(data: bytes) -> bytes:
    return bytes(b ^ 0x01 if b in _MARKERS else b for b in data)


class HostileFrames:
    """Deterministic hostile datagrams (seeded), one kind at a time, for one receiver."""

    def __init__(self, seed: int, *, to_server: bool, vehicle_sysid: int = VEHICLE_SYSID) -> None:
        self._rng = random.Random(seed)
        self._to_server = to_server
        self._vehicle_sysid = vehicle_sysid
        src = vehicle_sysid if to_server else STRANGER_SYSID
        self._mav = mavlink.MAVLink(None, srcSystem=src, srcComponent=1)
        self._unknown_ids = [i for i in range(1, 1 << 24, 4099)
                             if i not in mavlink.mavlink_map and i not in _UNKNOWN_IDS_TAKEN]

    def datagrams(self, count: int) -> Iterator[tuple[str, bytes]]:
        for i in range(count):
            kind = KINDS[i % len(KINDS)]
            yield kind, getattr(self, f"_{kind}")()

    def _pack(self, msg: Any) -> bytes:
        data = bytes(msg.pack(self._mav))
        self._mav.seq = (self._mav.seq + 1) % 256
        return data

    def _float(self) -> float:
        rng = self._rng
        return rng.choice(_ABSURD_FLOATS) if rng.random() < 0.7 else rng.uniform(-1e9, 1e9)

    def _good_frame(self) -> bytes:
        return self._pack(mavlink.MAVLink_attitude_message(
            self._rng.randrange(1 << 32), *(self._rng.uniform(-4, 4) for _ in range(6))))

    def _garbage(self) -> bytes:
        rng = self._rng
        return _no_markers(rng.randbytes(rng.randint(1, 280)))

    def _unknown_id(self) -> bytes:
        rng = self._rng
        length = rng.randint(0, 255)
        msg_id = rng.choice(self._unknown_ids)
        header = struct.pack("<BBBBBBBHB", mavlink.PROTOCOL_MARKER_V2, length, 0,
                             rng.randrange(256), rng.randrange(256), rng.randrange(256),
                             rng.randrange(256), msg_id & 0xFFFF, msg_id >> 16)
        return header + rng.randbytes(length) + rng.randbytes(2)

    def _truncated(self) -> bytes:
        frame = self._good_frame()
        return frame[: self._rng.randint(1, len(frame) - 1)]

    def _wrong_crc(self) -> bytes:
        frame = bytearray(self._good_frame())
        frame[-1 - self._rng.randrange(2)] ^= self._rng.randint(1, 255)
        return bytes(frame)

    def _oversized(self) -> bytes:
        rng = self._rng
        header = struct.pack("<BBBBBBBHB", mavlink.PROTOCOL_MARKER_V2, 255, 0, 0, 0,
                             STRANGER_SYSID, 1, mavlink.MAVLINK_MSG_ID_ATTITUDE, 0)
        payload = rng.randbytes(255)
        crc = mavlink.x25crc(header[1:] + payload)
        crc.accumulate(bytes([mavlink.MAVLink_attitude_message.crc_extra]))
        bad_crc = struct.pack("<H", crc.crc ^ 0x5A5A)
        return header + payload + bad_crc + _no_markers(rng.randbytes(rng.randint(1000, 8000)))

    def _absurd(self) -> bytes:
        rng = self._rng
        f = self._float
        target = OTHER_VEHICLE_SYSID
        choice = rng.randrange(6)
        msg: Any
        if choice == 0:
            msg = mavlink.MAVLink_heartbeat_message(
                mavlink.MAV_TYPE_GCS if not self._to_server else rng.randrange(256),
                rng.randrange(256), rng.randrange(256), rng.randrange(1 << 32),
                rng.randrange(256), rng.randrange(256))
        elif choice == 1:
            msg = mavlink.MAVLink_set_position_target_local_ned_message(
                rng.randrange(1 << 32), target, 1, rng.randrange(256), rng.randrange(1 << 16),
                *(f() for _ in range(11)))
        elif choice == 2:
            msg = mavlink.MAVLink_command_long_message(
                target, 1, rng.randrange(1 << 16), rng.randrange(256), *(f() for _ in range(7)))
        elif choice == 3:
            msg = mavlink.MAVLink_param_request_read_message(
                self._vehicle_sysid, 1, "".join(rng.choices(_PARAM_CHARS, k=16)).encode(),
                rng.randrange(-(1 << 15), 1 << 15))
        elif choice == 4:
            msg = mavlink.MAVLink_timesync_message(
                rng.randrange(-(1 << 63), 1 << 63), rng.randrange(-(1 << 63), 1 << 63))
        else:
            msg = mavlink.MAVLink_command_int_message(
                target, 1, rng.randrange(256), rng.randrange(1 << 16), 0, 0,
                *(f() for _ in range(4)), rng.randrange(-(1 << 31), 1 << 31),
                rng.randrange(-(1 << 31), 1 << 31), f())
        return self._pack(msg)


@dataclass
class EndResult:
    """What one receiver was sent and what it counted."""

    sent: dict[str, int] = field(default_factory=dict)
    expected: dict[str, int] = field(default_factory=dict)
    counted: dict[str, int] = field(default_factory=dict)

    @property
    def matches(self) -> bool:
        return self.expected == self.counted


@dataclass
class HostileResult:
    frames_per_end: int
    duration_s: float
    server: EndResult
    sim: EndResult
    datagrams_per_s: float
    setpoints_at_vehicle: int
    setpoint_rate_hz: float
    largest_setpoint_gap_s: float
    stayed_in_offboard: bool
    sim_partner_kept: bool
    vehicle_connected: bool
    disarm_ok: bool
    arm_again_ok: bool
    disarm_again_ok: bool
    sim_handler_errors: int
    kernel_drops_server: int | None = None
    kernel_drops_sim: int | None = None

    def as_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["server"]["matches"] = self.server.matches
        out["sim"]["matches"] = self.sim.matches
        return out


def kernel_drops(port: int) -> int | None:
    """Datagrams the kernel dropped for a full receive buffer on a loopback UDP port
    (/proc/net/udp's drops column); None where that file is not there."""
    try:
        lines = open("/proc/net/udp").read().splitlines()[1:]  # noqa: SIM115
    except OSError:
        return None
    for line in lines:
        fields = line.split()
        if int(fields[1].split(":")[1], 16) == port:
            return int(fields[-1])
    return None


def _expected(sent: Counter[str], outcome: dict[str, tuple[int, int, int]]) -> dict[str, int]:
    totals = [0, 0, 0]
    for kind, n in sent.items():
        for i, per in enumerate(outcome[kind]):
            totals[i] += per * n
    return {"bad": totals[0], "unverified": totals[1], "taken": totals[2]}


class _ErrorCounter:
    """Counts log records at ERROR and above (a handler that raised, caught by the link)."""

    def __init__(self) -> None:
        import logging

        self.count = 0
        outer = self

        class _Handler(logging.Handler):
            def emit(self, record: logging.LogRecord) -> None:
                outer.count += 1

        self._handler = _Handler(logging.ERROR)
        self._logger = logging.getLogger("sim")

    def __enter__(self) -> _ErrorCounter:
        self._logger.addHandler(self._handler)
        return self

    def __exit__(self, *exc: object) -> None:
        self._logger.removeHandler(self._handler)


async def _wait(condition: Any, timeout_s: float, what: str) -> None:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    while not condition():
        if loop.time() > deadline:
            raise TimeoutError(f"{what} not within {timeout_s} s")
        await asyncio.sleep(0.005)


async def run_hostile(frames_per_end: int, *, seed: int = 13, speed: float = 1.0,
                      ready_timeout_s: float = 30.0) -> HostileResult:
    """Fly, flood both ends with ``frames_per_end`` datagrams each, check, and report."""
    link = await Link.open(f"udpin:{LOOPBACK}:0")
    try:
        assert link.local_address is not None
        server_port = link.local_address[1]
        async with SimCluster(count=1, speed=speed, api_port=server_port) as sim:
            inst = sim.instances[0]
            return await _fly_and_flood(link, server_port, inst, frames_per_end, seed,
                                        ready_timeout_s)
    finally:
        await link.close()


async def _fly_and_flood(link: Link, server_port: int, inst: Any, frames_per_end: int,
                         seed: int, ready_timeout_s: float) -> HostileResult:
    await _wait(lambda: VEHICLE_SYSID in link.vehicles, ready_timeout_s, "discovery")
    vehicle = link.vehicles[VEHICLE_SYSID]
    assert isinstance(vehicle, Vehicle)
    await _wait(lambda: inst.vehicle.can_arm, ready_timeout_s, "ready to arm")
    await _wait(lambda: vehicle.snapshot().position_ned is not None
                and vehicle.snapshot().home is not None, ready_timeout_s, "position and home")
    await vehicle.set_param("COM_DISARM_PRFLT", 0.0)  # stay armed on the ground
    vehicle.stream_rate_hz = STREAM_RATE_HZ
    arm = await vehicle.arm()
    if not arm.ok:
        raise RuntimeError(f"arm refused: {arm}")
    offboard = await vehicle.start_offboard()
    if not offboard.ok:
        raise RuntimeError(f"offboard refused: {offboard}")
    server_addr = (LOOPBACK, server_port)
    assert inst.api_link.remote == server_addr

    arrivals: list[float] = []
    stranger_taken = 0
    loop = asyncio.get_running_loop()
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stranger.bind((LOOPBACK, 0))
    stranger.setblocking(False)
    stranger_addr = stranger.getsockname()

    def observe(sender: tuple[str, int], msg: Any) -> None:
        nonlocal stranger_taken
        if sender == stranger_addr:
            stranger_taken += 1
        elif msg.get_msgId() == mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED:
            arrivals.append(loop.time())

    inst.api_link.observe(observe)
    await _wait(lambda: len(arrivals) >= 5, 5.0, "setpoints at the vehicle")

    sim_c = inst.api_link.counters
    server_before = (link.stats().bad_frames, link.stats().unverified_frames)
    sim_before = (sim_c.rx_dropped, sim_c.rx_unverified)
    sent_server: Counter[str] = Counter()
    sent_sim: Counter[str] = Counter()
    left_offboard = False

    def server_counted() -> tuple[int, int]:
        s = link.stats()
        return s.bad_frames - server_before[0], s.unverified_frames - server_before[1]

    def sim_counted() -> tuple[int, int, int]:
        return (sim_c.rx_dropped - sim_before[0], sim_c.rx_unverified - sim_before[1],
                stranger_taken)

    def caught_up() -> bool:
        es, em = _expected(sent_server, SERVER_OUTCOME), _expected(sent_sim, SIM_OUTCOME)
        return (server_counted() == (es["bad"], es["unverified"])
                and sim_counted() == (em["bad"], em["unverified"], em["taken"]))

    to_server = HostileFrames(seed, to_server=True).datagrams(frames_per_end)
    to_sim = HostileFrames(seed + 1, to_server=False).datagrams(frames_per_end)
    started = loop.time()
    arrivals_before = len(arrivals)
    with _ErrorCounter() as errors:
        done = False
        while not done:
            window_bytes = 0
            for _ in range(WINDOW_DATAGRAMS // 2):
                pair = next(to_server, None), next(to_sim, None)
                if pair == (None, None):
                    done = True
                    break
                for item, port, sent in ((pair[0], server_port, sent_server),
                                         (pair[1], inst.api_local_port, sent_sim)):
                    if item is None:
                        continue
                    kind, data = item
                    stranger.sendto(data, (LOOPBACK, port))
                    sent[kind] += 1
                    window_bytes += len(data)
                if window_bytes > WINDOW_BYTES:
                    break
            try:
                await _wait(caught_up, 30.0, "receivers catching up")
            except TimeoutError as e:
                raise TimeoutError(
                    f"{e}: server sent {dict(sent_server)} expected "
                    f"{_expected(sent_server, SERVER_OUTCOME)} counted {server_counted()}; "
                    f"sim sent {dict(sent_sim)} expected {_expected(sent_sim, SIM_OUTCOME)} "
                    f"counted {sim_counted()}") from None
            left_offboard = left_offboard or inst.vehicle.mode_name != "OFFBOARD"
        duration_s = loop.time() - started
        window = [t for t in arrivals[arrivals_before:] if t >= started]
        gaps = [b - a for a, b in itertools.pairwise(window)]
        partner_kept = inst.api_link.remote == server_addr
        connected = vehicle.snapshot().connected
        disarm = await vehicle.disarm()
        if vehicle.streamer_active:
            await vehicle.stop_offboard()
        arm_again = await vehicle.arm()
        disarm_again = await vehicle.disarm()
    stranger.close()
    es, em = _expected(sent_server, SERVER_OUTCOME), _expected(sent_sim, SIM_OUTCOME)
    sc, mc = server_counted(), sim_counted()
    return HostileResult(
        frames_per_end=frames_per_end,
        duration_s=round(duration_s, 3),
        server=EndResult(dict(sent_server), {"bad": es["bad"], "unverified": es["unverified"]},
                         {"bad": sc[0], "unverified": sc[1]}),
        sim=EndResult(dict(sent_sim), em, {"bad": mc[0], "unverified": mc[1], "taken": mc[2]}),
        datagrams_per_s=round((sum(sent_server.values()) + sum(sent_sim.values()))
                              / duration_s, 1),
        setpoints_at_vehicle=len(window),
        setpoint_rate_hz=round(len(window) / duration_s, 2),
        largest_setpoint_gap_s=round(max(gaps, default=math.inf), 4),
        stayed_in_offboard=not left_offboard,
        sim_partner_kept=partner_kept,
        vehicle_connected=connected,
        disarm_ok=disarm.ok,
        arm_again_ok=arm_again.ok,
        disarm_again_ok=disarm_again.ok,
        sim_handler_errors=errors.count,
        kernel_drops_server=kernel_drops(server_port),
        kernel_drops_sim=kernel_drops(inst.api_local_port),
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=DEFAULT_FRAMES,
                        help=f"datagrams per end (the long run: {LONG_FRAMES})")
    parser.add_argument("--seed", type=int, default=13)
    args = parser.parse_args()
    load_before = os.getloadavg()
    wall = time.monotonic()
    result = asyncio.run(run_hostile(args.frames, seed=args.seed))
    out = result.as_json()
    out["wall_s"] = round(time.monotonic() - wall, 1)
    out["machine"] = machine_info(load_before)
    for key in ("frames_per_end", "duration_s", "datagrams_per_s", "setpoint_rate_hz",
                "largest_setpoint_gap_s", "stayed_in_offboard", "sim_partner_kept",
                "vehicle_connected", "disarm_ok", "arm_again_ok", "disarm_again_ok",
                "sim_handler_errors", "kernel_drops_server", "kernel_drops_sim"):
        print(f"{key:24} {out[key]}")
    for end in ("server", "sim"):
        print(f"{end:6} sent {out[end]['sent']}")
        print(f"{end:6} expected {out[end]['expected']} counted {out[end]['counted']}"
              f" -> {'match' if out[end]['matches'] else 'MISMATCH'}")
    write_results("hostile_input", out)
    ok = (result.server.matches and result.sim.matches and result.stayed_in_offboard
          and result.sim_partner_kept and result.disarm_ok and result.arm_again_ok
          and result.disarm_again_ok)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())


def report(result: dict[str, Any]) -> Section | None:
    """Counters against what was sent, and what the flight kept doing."""
    rows = []
    for end in ("server", "sim"):
        r = result[end]
        for counter, expected in r["expected"].items():
            rows.append([end, counter, expected, r["counted"].get(counter),
                         "match" if r["counted"].get(counter) == expected else "**MISMATCH**"])
    checks = ["stayed_in_offboard", "sim_partner_kept", "vehicle_connected", "disarm_ok",
              "arm_again_ok", "disarm_again_ok"]
    kept = [name.replace("_", " ") for name in checks if result.get(name)]
    lost = [name.replace("_", " ") for name in checks if not result.get(name)]
    markdown = (
        f"{result['frames_per_end']} malformed or hostile datagrams into each end "
        f"({result['datagrams_per_s']:.0f} datagrams/s for {result['duration_s']:.0f} s) while "
        f"the server streamed 50 Hz setpoints: the stream reached the vehicle at "
        f"{ratio(result['setpoint_rate_hz'], 50.0)} of its rate with a largest gap of "
        f"{result['largest_setpoint_gap_s'] * 1e3:.0f} ms; {result['sim_handler_errors']} "
        f"handler errors; kernel drops {result['kernel_drops_server']} (server) and "
        f"{result['kernel_drops_sim']} (sim). Held: {', '.join(kept) or 'none'}"
        + (f"; **not held: {', '.join(lost)}**" if lost else "") + ".\n\n"
        + table(["end", "counter", "expected", "counted", ""], rows))
    return Section("Hostile input during a flight", 100, markdown)
