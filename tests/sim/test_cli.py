"""`python -m sim` as a process: ready line, ports, and clean stops."""

from __future__ import annotations

import contextlib
import json
import math
import os
import select
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.process.cli import (
    SITL_API_LOCAL_PORT,
    SITL_API_REMOTE_PORT,
    SITL_GCS_LOCAL_PORT,
    SITL_GCS_REMOTE_PORT,
    VEHICLES_PER_PROCESS,
    _child_arguments,
    build_parser,
    process_count,
)
from sim.process.sim_processes import split_instances

README = Path(__file__).resolve().parents[2] / "README.md"

EPHEMERAL = ["--api-port", "0", "--gcs-port", "0", "--api-local-port", "0",
             "--gcs-local-port", "0"]


def start_sim(*extra: str, env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "sim", "--ready-json", "--speed", "5", *EPHEMERAL, *extra],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=None if env is None else {**os.environ, **env},
    )


def read_ready(proc: subprocess.Popen[str]) -> dict[str, Any]:
    assert proc.stdout is not None
    line = proc.stdout.readline()
    ready: dict[str, Any] = json.loads(line)
    return ready


def stop(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.kill()
        proc.wait(5)


def test_defaults_are_px4_sitl_ports() -> None:
    args = build_parser().parse_args([])
    assert (args.api_port, args.gcs_port) == (SITL_API_REMOTE_PORT, SITL_GCS_REMOTE_PORT)
    assert (args.api_local_port, args.gcs_local_port) == (SITL_API_LOCAL_PORT, SITL_GCS_LOCAL_PORT)
    assert (args.airframe, args.count, args.speed) == ("quad", 1, 1.0)


def test_readme_port_table_shows_the_defaults() -> None:
    text = README.read_text()
    api_row = f"| API / offboard | {SITL_API_LOCAL_PORT} + i | {SITL_API_REMOTE_PORT} + i |"
    gcs_row = f"| GCS | {SITL_GCS_LOCAL_PORT} + i | {SITL_GCS_REMOTE_PORT} (shared) |"
    assert api_row in text
    assert gcs_row in text


def test_ready_json_lists_instances_and_the_sim_answers_on_them() -> None:
    proc = start_sim("--count", "2", "--exit-on-stdin-eof")
    try:
        ready = read_ready(proc)
        assert ready["event"] == "ready"
        instances = ready["instances"]
        assert [(i["instance"], i["sysid"]) for i in instances] == [(0, 1), (1, 2)]
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(5.0)
        mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        hb = mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)
        sock.sendto(hb.pack(mav), ("127.0.0.1", instances[1]["gcs_local_port"]))
        parser = mavlink.MAVLink(None)
        deadline = time.monotonic() + 5.0
        heartbeat = None
        while heartbeat is None and time.monotonic() < deadline:
            for msg in parser.parse_buffer(sock.recv(65536)) or []:
                if msg.get_type() == "HEARTBEAT":
                    heartbeat = msg
        sock.close()
        assert heartbeat is not None
        assert heartbeat.get_srcSystem() == 2
        assert proc.stdin is not None
        proc.stdin.close()  # parent gone: the sim follows
        assert proc.wait(10) == 0
    finally:
        stop(proc)


def test_px4_param_variables_set_parameters_at_start_as_px4_sitl_does() -> None:
    """PX4 SITL's rcS sets PX4_PARAM_<name>=<value> at start; so does the sim, and a name
    it lacks is said, not fatal."""
    proc = start_sim("--exit-on-stdin-eof", env={
        "PX4_PARAM_COM_DISARM_PRFLT": "80", "PX4_PARAM_NAV_DLL_ACT": "2",
        "PX4_PARAM_NO_SUCH_PARAM": "1"})  # fmt: skip
    try:
        port = read_ready(proc)["instances"][0]["gcs_local_port"]
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(1.0)
        mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        parser = mavlink.MAVLink(None)
        values: dict[str, float] = {}
        deadline = time.monotonic() + 20.0
        while len(values) < 2 and time.monotonic() < deadline:
            for name in ("COM_DISARM_PRFLT", "NAV_DLL_ACT"):
                read = mavlink.MAVLink_param_request_read_message(1, 1, name.encode(), -1)
                sock.sendto(read.pack(mav), ("127.0.0.1", port))
            with contextlib.suppress(TimeoutError):
                for msg in parser.parse_buffer(sock.recv(65536)) or []:
                    if msg.get_type() == "PARAM_VALUE":
                        values[msg.param_id] = msg.param_value
        sock.close()
        assert values["COM_DISARM_PRFLT"] == 80.0
        assert struct.unpack("<i", struct.pack("<f", values["NAV_DLL_ACT"])) == (2,)  # INT32
        assert proc.stdin is not None
        proc.stdin.close()
        assert proc.wait(10) == 0
        assert proc.stderr is not None
        assert "PX4_PARAM_NO_SUCH_PARAM: this vehicle has no parameter NO_SUCH_PARAM" in (
            proc.stderr.read())
    finally:
        stop(proc)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_stops_cleanly_on_signal(sig: signal.Signals) -> None:
    proc = start_sim()
    try:
        read_ready(proc)
        proc.send_signal(sig)
        assert proc.wait(10) == 0
    finally:
        stop(proc)


def _heartbeat_from(port: int) -> int:
    """Say HEARTBEAT to a sim port; the sysid of the first HEARTBEAT that comes back."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(5.0)
    try:
        mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        sock.sendto(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(mav),
                    ("127.0.0.1", port))
        parser = mavlink.MAVLink(None)
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            for msg in parser.parse_buffer(sock.recv(65536)) or []:
                if msg.get_type() == "HEARTBEAT":
                    return int(msg.get_srcSystem())
        raise AssertionError(f"no HEARTBEAT from port {port}")
    finally:
        sock.close()


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1][0]
    except FileNotFoundError:
        return False
    return state != "Z"


def test_process_count_and_split_keep_instance_numbers_and_base_ports() -> None:
    assert process_count(50, 0) == math.ceil(50 / VEHICLES_PER_PROCESS)
    assert process_count(1, 0) == 1
    assert process_count(3, 2) == 2
    assert process_count(2, 5) == 2  # never a process without a vehicle
    assert split_instances(4, 7, 3) == [(4, 3), (7, 2), (9, 2)]
    args = build_parser().parse_args(
        ["--instance", "4", "--count", "7", "--processes", "3", "--api-port", "20000",
         "--gcs-port", "20100", "--api-local-port", "20200", "--gcs-local-port", "0",
         "--speed", "2.5", "--airframe", "hexa"])
    child = build_parser().parse_args(_child_arguments(args, 7, 2))
    assert (child.instance, child.count, child.processes) == (7, 2, 1)
    assert (child.airframe, child.speed, child.ready_json, child.exit_on_stdin_eof) == (
        "hexa", 2.5, True, True)
    # the child adds its first instance to the same bases: instance 7 keeps its ports
    assert (child.api_port, child.gcs_port, child.api_local_port, child.gcs_local_port) == (
        20000, 20100, 20200, 0)


def test_count_over_processes_reports_all_instances_answers_and_stops_them_all() -> None:
    proc = start_sim("--count", "3", "--processes", "2", "--exit-on-stdin-eof")
    try:
        ready = read_ready(proc)
        instances = ready["instances"]
        assert [(i["instance"], i["sysid"]) for i in instances] == [(0, 1), (1, 2), (2, 3)]
        ports = [i[key] for i in instances for key in ("api_local_port", "gcs_local_port")]
        assert len(set(ports)) == 6
        pids = ready["pids"]
        assert len(pids) == 2
        assert all(_alive(pid) for pid in pids)
        # a vehicle of each process answers as itself
        assert _heartbeat_from(instances[0]["api_local_port"]) == 1
        assert _heartbeat_from(instances[2]["gcs_local_port"]) == 3
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
        assert not any(_alive(pid) for pid in pids)
    finally:
        stop(proc)


def test_a_process_that_dies_takes_the_others_down() -> None:
    proc = start_sim("--count", "2", "--processes", "2")
    try:
        pids = read_ready(proc)["pids"]
        os.kill(pids[1], signal.SIGKILL)
        assert proc.wait(15) == 1
        assert not _alive(pids[0])
    finally:
        stop(proc)


Times = list[tuple[float, float]]  # (received_s, the vehicle's own s) of each ATTITUDE


class _Listener:
    """A ground station on one vehicle's port (the vehicle answers its first sender)."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.parser = mavlink.MAVLink(None)
        mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.sock.sendto(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(mav),
                         ("127.0.0.1", port))

    def attitude_times_s(self, received_s: float) -> Times:
        """(received_s, the vehicle's time_boot_ms in s) of each ATTITUDE in one datagram."""
        data = self.sock.recv(65536)
        return [(received_s, msg.time_boot_ms / 1000.0)
                for msg in self.parser.parse_buffer(data) or [] if msg.get_type() == "ATTITUDE"]


def _attitudes(vehicles: list[_Listener], seconds: float) -> dict[_Listener, Times]:
    """(received_s, the vehicle's s) of each ATTITUDE every vehicle sends over `seconds`."""
    seen: dict[_Listener, Times] = {v: [] for v in vehicles}
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        ready, _, _ = select.select([v.sock for v in vehicles], [], [], left)
        now = time.monotonic()
        for vehicle in vehicles:
            if vehicle.sock in ready:
                seen[vehicle] += vehicle.attitude_times_s(now)
    return seen


def _clock_rates(vehicles: list[_Listener], window_s: float = 1.5) -> list[float]:
    """How fast each vehicle's clock runs against this process's wall clock over `window_s`
    (read from every vehicle at once, once each streams, after what waited in the sockets)."""
    deadline = time.monotonic() + 15.0
    while not all(_attitudes([v], 0.2)[v] for v in vehicles):  # booted: streaming
        assert time.monotonic() < deadline, "no ATTITUDE"
    for vehicle in vehicles:
        vehicle.sock.setblocking(False)
        with contextlib.suppress(BlockingIOError):
            while True:
                vehicle.attitude_times_s(0.0)
    rates = []
    for times in _attitudes(vehicles, window_s).values():
        (wall0, sim0), (wall1, sim1) = times[0], times[-1]
        assert wall1 - wall0 > window_s / 2, times
        rates.append((sim1 - sim0) / (wall1 - wall0))
    return rates


def test_sigusr1_fast_forwards_every_vehicle_and_sigusr2_goes_back() -> None:
    # two processes: the parent passes the signals on, each child's own handler takes them
    proc = start_sim("--count", "2", "--processes", "2", "--speed", "1",
                     "--fast-forward-speed", "6")
    try:
        vehicles = [_Listener(i["gcs_local_port"]) for i in read_ready(proc)["instances"]]
        try:
            assert all(0.7 < rate < 1.3 for rate in _clock_rates(vehicles))
            proc.send_signal(signal.SIGUSR1)
            # 6x asked; a loaded machine may run it slower, never as slow as real time
            assert all(3.0 < rate < 6.5 for rate in _clock_rates(vehicles))
            proc.send_signal(signal.SIGUSR2)
            assert all(0.7 < rate < 1.3 for rate in _clock_rates(vehicles))
            assert proc.poll() is None
        finally:
            for vehicle in vehicles:
                vehicle.sock.close()
    finally:
        stop(proc)


@pytest.mark.parametrize("value", ["0", "-2", "inf", "nan"])
def test_a_fast_forward_speed_that_is_not_positive_exits_2(value: str) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "sim", "--fast-forward-speed", value, *EPHEMERAL],
        capture_output=True, text=True, timeout=30,
    )
    assert result.returncode == 2
    assert "--fast-forward-speed must be positive" in result.stderr
