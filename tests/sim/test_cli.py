"""`python -m sim` as a process: ready line, ports, and clean stops."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.cli import (
    SITL_API_LOCAL_PORT,
    SITL_API_REMOTE_PORT,
    SITL_GCS_LOCAL_PORT,
    SITL_GCS_REMOTE_PORT,
    build_parser,
)

README = Path(__file__).resolve().parents[2] / "README.md"

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


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_stops_cleanly_on_signal(sig: signal.Signals) -> None:
    proc = start_sim()
    try:
        read_ready(proc)
        proc.send_signal(sig)
        assert proc.wait(10) == 0
    finally:
        stop(proc)
