"""A fleet on one machine, as separate processes: a fleet server (`skyhelm serve --fleet`, no
vehicle of its own) and two edges (`skyhelm serve --zenoh --sim-count 1`, each with its
simulated vehicle), Zenoh on loopback only with explicit endpoints and multicast scouting off.

Two topologies:
- peer: the fleet server listens, the edges connect to it (peer mode, brokerless);
- router: `skyhelm router` listens, everyone connects to it as a client.

Every process can be killed the hard way (SIGKILL) and an edge restarted under its name.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import select
import signal
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import httpx

from tests.fleet.fake_edge import free_tcp_endpoint
from tests.serve_process import READY_PREFIX, SKYHELM, _first_line, _stop
from tests.waiting import wait_for_blocking

REPO = Path(__file__).resolve().parents[2]
Topology = Literal["peer", "router"]
FLEET = "rigfleet"
EDGES = ("edge-a", "edge-b")
# simulated seconds per wall second: flights finish sooner, the machine can still keep up
SIM_SPEED = 4.0


@dataclass
class Process:
    name: str
    command: list[str]
    log_path: Path
    popen: subprocess.Popen[str] | None = None
    base_url: str = ""

    @property
    def api(self) -> str:
        return f"{self.base_url}/api/v1"

    def launch(self) -> None:
        with self.log_path.open("a") as log:
            self.popen = subprocess.Popen(
                self.command, stdout=subprocess.PIPE, stderr=log, text=True, cwd=REPO,
                env={**os.environ, "PYTHONPATH": str(REPO)},
            )

    def wait_ready(self, timeout_s: float = 90.0) -> None:
        """Until it printed its URL (its vehicles, if any, talking)."""
        assert self.popen is not None
        line = _first_line(self.popen, timeout_s, self.log_path)
        self.base_url = line.removeprefix(READY_PREFIX).strip().partition("/?token=")[0]

    def kill(self) -> None:
        """SIGKILL: no goodbye on Zenoh, sockets closed by the kernel."""
        if self.popen is not None and self.popen.poll() is None:
            self.popen.send_signal(signal.SIGKILL)
            self.popen.wait(timeout=10)

    def signal(self, signum: int) -> None:
        assert self.popen is not None
        self.popen.send_signal(signum)

    def stop(self) -> None:
        if self.popen is not None:
            _stop(self.popen)
            if self.popen.stdout is not None:
                self.popen.stdout.close()


@dataclass
class FleetRig:
    topology: Topology
    pilot: str
    observer: str
    fleet: Process
    edges: dict[str, Process]
    fleet_endpoint: str
    router_endpoint: str | None = None
    router: subprocess.Popen[bytes] | None = None
    http: httpx.Client = field(default_factory=lambda: httpx.Client(timeout=30.0))

    def auth(self, token: str | None = None, lease_id: str | None = None) -> dict[str, str]:
        headers = {"Authorization": f"Bearer {token or self.pilot}"}
        if lease_id:
            headers["X-Lease-Id"] = lease_id
        return headers

    def fleet_get(self, path: str, token: str | None = None) -> Any:
        answer = self.http.get(f"{self.fleet.api}{path}", headers=self.auth(token))
        assert answer.status_code == 200, (path, answer.status_code, answer.text)
        return answer.json()

    def via_fleet(
        self, method: str, edge: str, path: str, body: Any = None, *,
        token: str | None = None, lease_id: str | None = None,
    ) -> httpx.Response:
        """A call to `/vehicles/1/<path>` of an edge, through the fleet server."""
        url = f"{self.fleet.api}/fleet/edges/{edge}/vehicles/1/{path}"
        return self.http.request(
            method, url, json=body, headers=self.auth(token, lease_id)
        )

    def alive(self) -> dict[str, bool]:
        """key -> alive, as the fleet server lists its vehicles now."""
        return {row["key"]: row["alive"] for row in self.fleet_get("/fleet/vehicles")}

    def wait_alive(self, keys: list[str], timeout_s: float = 60.0) -> None:
        wait_for_blocking(
            f"{keys} alive in the fleet",
            lambda: all(self.alive().get(key) for key in keys) or None,
            timeout_s,
        )

    def restart_edge(self, name: str) -> None:
        """The edge again, under its name (a fresh listen port: the old one may linger)."""
        old = self.edges[name]
        old.stop()
        new = edge_process(
            name, old.log_path.parent, self.pilot, self.observer, self.topology,
            self.router_endpoint, self.fleet_endpoint,
        )
        self.edges[name] = new
        new.launch()
        new.wait_ready()

    def close(self) -> None:
        for process in (self.fleet, *self.edges.values()):
            process.stop()
        if self.router is not None:
            self.router.terminate()  # SIGTERM: the router closes its session and exits
            try:
                self.router.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.router.kill()
                self.router.wait()
            if self.router.stdout is not None:
                self.router.stdout.close()
        self.http.close()


def zenoh_flags(topology: Topology, router: str | None, fleet_endpoint: str) -> list[str]:
    if topology == "router":
        assert router is not None
        return ["--zenoh-mode", "client", "--zenoh-connect", router]
    return ["--zenoh-connect", fleet_endpoint]


def serve_command(
    log_dir: Path, pilot: str, observer: str, *args: str
) -> list[str]:
    return [
        str(SKYHELM), "serve", "--port", "0", f"--token={pilot}", f"--observer-token={observer}",
        "--log-dir", str(log_dir), "--no-scene", "--fleet-name", FLEET,
        "--no-zenoh-multicast-scouting", *args,
    ]


def edge_process(
    name: str, log_dir: Path, pilot: str, observer: str, topology: Topology,
    router: str | None, fleet_endpoint: str,
) -> Process:
    flags = zenoh_flags(topology, router, fleet_endpoint)
    if topology == "peer":
        # a peer listens somewhere: on loopback, not Zenoh's default of every interface
        flags += ["--zenoh-listen", free_tcp_endpoint()]
    command = serve_command(
        log_dir, pilot, observer, "--zenoh", "--edge-name", name, "--sim-count", "1",
        "--sim-speed", str(SIM_SPEED), *flags,
    )
    return Process(name, command, log_dir / f"{name}.stderr.log")


@contextlib.contextmanager
def fleet_rig(topology: Topology, log_dir: Path) -> Iterator[FleetRig]:
    pilot, observer = secrets.token_urlsafe(16), secrets.token_urlsafe(16)
    fleet_endpoint = free_tcp_endpoint()
    router: subprocess.Popen[bytes] | None = None
    router_endpoint: str | None = None
    if topology == "router":
        router_endpoint = free_tcp_endpoint()
        router = start_router(router_endpoint, log_dir / "router.stderr.log")
        fleet_flags = zenoh_flags(topology, router_endpoint, fleet_endpoint)
    else:
        fleet_flags = ["--zenoh-listen", fleet_endpoint]
    fleet = Process(
        "fleet",
        serve_command(log_dir, pilot, observer, "--fleet", *fleet_flags),
        log_dir / "fleet.stderr.log",
    )
    edges = {
        name: edge_process(name, log_dir, pilot, observer, topology, router_endpoint,
                           fleet_endpoint)
        for name in EDGES
    }
    rig = FleetRig(
        topology, pilot, observer, fleet, edges, fleet_endpoint, router_endpoint, router
    )
    try:
        for process in (fleet, *edges.values()):
            process.launch()
        for process in (fleet, *edges.values()):
            process.wait_ready()
        yield rig
    finally:
        rig.close()


def start_router(endpoint: str, log_path: Path) -> subprocess.Popen[bytes]:
    """`skyhelm router` listening on ``endpoint``; returns once it says it is ready."""
    with log_path.open("a") as log:
        # unbuffered bytes: select() then sees every line not yet read
        router = subprocess.Popen(
            [str(SKYHELM), "router", "--listen", endpoint],
            stdout=subprocess.PIPE, stderr=log, bufsize=0, cwd=REPO,
        )
    assert router.stdout is not None
    deadline = time.monotonic() + 60.0
    seen: list[str] = []
    while time.monotonic() < deadline:
        readable, _, _ = select.select([router.stdout], [], [], 0.2)
        if not readable:
            assert router.poll() is None, f"router exited: {log_path.read_text()[-2000:]}"
            continue
        line = router.stdout.readline().decode(errors="replace")
        assert line, f"router closed its output after {seen}: {log_path.read_text()[-2000:]}"
        seen.append(line.strip())
        if line.startswith("SkyHelm router ready"):
            return router
    router.kill()
    raise AssertionError(f"router not ready within 60 s; it said {seen}")
