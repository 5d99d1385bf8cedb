"""`python -m sim` as a process: ready line, ports, and clean stops."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from typing import Any

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.cli import build_parser

EPHEMERAL = ["--api-port", "0", "--gcs-port", "0", "--api-local-port", "0",
             "--gcs-local-port", "0"]


def start_sim(*extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "sim", "--ready-json", "--speed", "5", *EPHEMERAL, *extra],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
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
    assert (args.api_port, args.gcs_port) == (14540, 14550)
    assert (args.api_local_port, args.gcs_local_port) == (14580, 18570)
    assert (args.airframe, args.count, args.speed) == ("quad", 1, 1.0)


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


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_stops_cleanly_on_signal(sig: signal.Signals) -> None:
    proc = start_sim()
    try:
        read_ready(proc)
        proc.send_signal(sig)
        assert proc.wait(10) == 0
    finally:
        stop(proc)
