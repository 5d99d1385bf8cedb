"""Real PX4 v1.16 SITL (the kit in shared/px4-sitl: SIH, headless), opt-in with `make test-px4`.

The kit is found in $SKYHELM_PX4_SITL_DIR (default /root/px4sitl); without a build every test
here is skipped. The instance number comes from $SKYHELM_PX4_INSTANCE (default: the first one
whose ports are free, as other PX4 instances may run on the machine). Its MAVLink
ports are not written here: they follow the layout the kit's run.sh documents
("API/offboard:  PX4 127.0.0.1:(A+N) -> 127.0.0.1:(B+N)"), read from that file, so a kit with
another layout still works; $SKYHELM_PX4_API_PORT overrides the port SkyHelm listens on.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.serve_process import Served, skyhelm_serve

DEFAULT_SITL_DIR = Path("/root/px4sitl")
MODEL = "sihsim_quadx"
# Instances tried when SKYHELM_PX4_INSTANCE does not name one.
_INSTANCES = 10
_API_LAYOUT = re.compile(r"API/offboard:\s*PX4 [\d.]+:\((\d+)\+N\)\s*->\s*([\d.]+):\((\d+)\+N\)")


@dataclass(frozen=True)
class Px4Sitl:
    """Where one PX4 instance talks to its onboard (API) client."""

    sitl_dir: Path
    instance: int
    api_host: str
    api_port: int

    @property
    def sysid(self) -> int:
        return self.instance + 1  # run.sh: MAVLink system id N+1

    @property
    def connect_url(self) -> str:
        return f"udpin:{self.api_host}:{self.api_port}"


def sitl_dir() -> Path:
    return Path(os.environ.get("SKYHELM_PX4_SITL_DIR") or DEFAULT_SITL_DIR)


def find_sitl() -> Px4Sitl:
    """The configured instance of the kit, or a skip saying what is missing."""
    root = sitl_dir()
    run_sh = root / "run.sh"
    binary = root / "build" / "px4_sitl_default" / "bin" / "px4"
    if not run_sh.is_file() or not binary.is_file():
        pytest.skip(
            f"no PX4 SITL build in {root} (set SKYHELM_PX4_SITL_DIR to the kit built by "
            "shared/px4-sitl/build.sh)"
        )
    layout = _API_LAYOUT.search(run_sh.read_text())
    if layout is None:
        pytest.skip(f"{run_sh} does not document its API port layout")
    px4_base, host, client_base = layout.groups()
    chosen = os.environ.get("SKYHELM_PX4_INSTANCE")
    # Without a choice: the first instance whose two ports nobody uses (others may fly PX4 here).
    instance = (
        int(chosen)
        if chosen is not None
        else next(
            (
                n
                for n in range(_INSTANCES)
                if _udp_free(host, int(px4_base) + n) and _udp_free(host, int(client_base) + n)
            ),
            -1,
        )
    )
    if instance < 0:
        pytest.skip(f"all of PX4 instances 0..{_INSTANCES - 1} are in use")
    port = int(os.environ.get("SKYHELM_PX4_API_PORT") or int(client_base) + instance)
    return Px4Sitl(root, instance, host, port)


def _udp_free(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind((host, port))
        except OSError:
            return False
        return True


@pytest.fixture(scope="module")
def px4() -> Iterator[Px4Sitl]:
    """A fresh PX4 instance (clean parameters) for the module; stopped afterwards."""
    sitl = find_sitl()
    started = subprocess.run(
        [str(sitl.sitl_dir / "run.sh"), str(sitl.instance), MODEL],
        env={**os.environ, "PX4_CLEAN": "1"},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert started.returncode == 0, f"run.sh failed: {started.stdout}{started.stderr}"
    pid = int(started.stdout.strip().splitlines()[-1])
    try:
        yield sitl
    finally:
        _stop(pid)


def _stop(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.1)  # polling a process that is not ours to wait() for
    os.kill(pid, signal.SIGKILL)


@pytest.fixture(scope="module")
def served_px4(px4: Px4Sitl, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    """`skyhelm serve --connect udpin:...` with default settings, talking to the instance."""
    log_dir = tmp_path_factory.mktemp("px4-serve")
    with skyhelm_serve(log_dir, "--connect", px4.connect_url, "--no-scene") as served:
        yield served


@dataclass
class Px4Process:
    """One PX4 instance started by the kit's run.sh, which a test may restart."""

    sitl: Px4Sitl
    pid: int = 0

    def start(self, *, clean: bool) -> None:
        env = {**os.environ, "PX4_CLEAN": "1" if clean else "0"}
        started = subprocess.run(
            [str(self.sitl.sitl_dir / "run.sh"), str(self.sitl.instance), MODEL],
            env=env, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert started.returncode == 0, f"run.sh failed: {started.stdout}{started.stderr}"
        self.pid = int(started.stdout.strip().splitlines()[-1])

    def stop(self) -> None:
        if self.pid:
            _stop(self.pid)
            self.pid = 0


@pytest.fixture
def px4_process() -> Iterator[Px4Process]:
    process = Px4Process(find_sitl())
    process.start(clean=True)
    try:
        yield process
    finally:
        process.stop()
