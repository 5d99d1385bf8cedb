"""Run docker/fleet.compose.yaml's services as plain processes on 127.0.0.1, for a machine
where Docker cannot run containers: the same commands, with the compose network's names and
wildcard addresses replaced by loopback and the router's port by a free one; then check that
the fleet server lists every edge's vehicle alive with a state. Exit 0 when it does.

    .venv/bin/python docker/run_fleet_locally.py [--keep]    # --keep: run until Ctrl-C
"""

from __future__ import annotations

import argparse
import os
import queue
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import yaml

COMPOSE = Path(__file__).resolve().parent / "fleet.compose.yaml"
SKYHELM = Path(sys.executable).with_name("skyhelm")
READY = ("SkyHelm ready: ", "SkyHelm router ready")


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def local_command(command: list[str], router_port: int) -> list[str]:
    """A compose command on loopback: the router's name and port, wildcard hosts, port 0."""
    out = [
        arg.replace("tcp/router:7447", f"tcp/127.0.0.1:{router_port}")
        .replace("tcp/0.0.0.0:7447", f"tcp/127.0.0.1:{router_port}")
        .replace("0.0.0.0", "127.0.0.1")
        for arg in command
    ]
    if out[0] == "serve":
        out += ["--port", "0", "--no-scene"]
    return out


def compose_environment(service: dict[str, Any], host: dict[str, str]) -> dict[str, str]:
    """What compose puts in a service's environment from ``host``'s variables: ``NAME=value``
    with ``${VAR:?…}`` / ``${VAR:-default}`` resolved, and a bare ``NAME`` only when set."""
    env: dict[str, str] = {}
    for entry in service.get("environment") or []:
        name, sep, value = str(entry).partition("=")
        if not sep:
            if name in host:
                env[name] = host[name]
            continue
        if value.startswith("${") and value.endswith("}"):
            variable, _, rest = value[2:-1].partition(":")
            if host.get(variable):
                value = host[variable]
            elif rest.startswith("-"):
                value = rest[1:]
            else:
                raise SystemExit(f"{variable}: {rest[1:] or 'must be set'}")
        env[name] = value
    return env


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", action="store_true", help="keep running until Ctrl-C")
    args = parser.parse_args(argv)
    services: dict[str, Any] = yaml.safe_load(COMPOSE.read_text())["services"]
    token = secrets.token_urlsafe(24)
    router_port = _free_port()
    logs = Path(tempfile.mkdtemp(prefix="skyhelm-fleet-local-"))
    lines: queue.Queue[tuple[str, str]] = queue.Queue()
    processes: dict[str, subprocess.Popen[str]] = {}
    urls: dict[str, str] = {}
    # the router first, as compose's depends_on orders them
    order = sorted(services, key=lambda name: name != "router")
    ok = False
    try:
        for name in order:
            service = services[name]
            command = local_command([str(a) for a in service["command"]], router_port)
            if command[0] == "serve":
                command += ["--log-dir", str(logs / name)]
            print(f"{name}: skyhelm {' '.join(command)}", flush=True)
            process = subprocess.Popen(
                [str(SKYHELM), *command], stdout=subprocess.PIPE,
                stderr=(logs / f"{name}.stderr.log").open("w"), text=True,
                env={**os.environ, **compose_environment(
                    service, {**os.environ, "SKYHELM_TOKEN": token})},
            )
            processes[name] = process
            stdout = process.stdout
            assert stdout is not None
            threading.Thread(target=lambda n=name, out=stdout: [lines.put((n, x)) for x in out],
                             daemon=True).start()
            deadline = time.monotonic() + 90.0
            while name not in urls:
                if process.poll() is not None or time.monotonic() > deadline:
                    print(f"{name} did not start: see {logs / (name + '.stderr.log')}")
                    return 1
                try:
                    who, line = lines.get(timeout=0.5)
                except queue.Empty:
                    continue
                if line.startswith(READY):
                    urls[who] = line.removeprefix("SkyHelm ready: ").split("/?token=")[0].strip()
        fleet_url = urls["fleet"]
        edges = [n for n in services if "--zenoh" in services[n]["command"]]
        deadline = time.monotonic() + 60.0
        rows: list[dict[str, Any]] = []
        with httpx.Client(headers={"Authorization": f"Bearer {token}"}, timeout=10.0) as client:
            while time.monotonic() < deadline:
                rows = client.get(f"{fleet_url}/api/v1/fleet/vehicles").json()
                seen = {r["edge"] for r in rows if r["alive"] and r["state_age_s"] is not None}
                if seen >= set(edges):
                    break
                time.sleep(0.5)
        for row in rows:
            print(f"fleet vehicle {row['key']}: alive {row['alive']}, {row['type']}, "
                  f"{row['mode']}, state age {row['state_age_s']} s")
        ok = {r["edge"] for r in rows if r["alive"]} >= set(edges)
        print("the fleet server lists every edge's vehicle" if ok else f"MISSING edges: {logs}")
        if ok and args.keep:
            print(f"fleet dashboard: {fleet_url}/?token={token}  (Ctrl-C stops)")
            try:
                while True:
                    time.sleep(1.0)
            except KeyboardInterrupt:
                pass
        return 0 if ok else 1
    finally:
        for process in reversed(list(processes.values())):
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for process in processes.values():
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
        if ok:
            shutil.rmtree(logs, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
