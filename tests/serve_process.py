"""`skyhelm serve` as a user starts it: a real subprocess on an ephemeral port, found by the
one URL it prints, stopped with Ctrl-C (SIGINT) afterwards."""

from __future__ import annotations

import contextlib
import os
import secrets
import select
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

SKYHELM = Path(sys.executable).with_name("skyhelm")
READY_PREFIX = "SkyHelm ready: "


@dataclass(frozen=True)
class Served:
    """What a script needs to talk to a running server."""

    base_url: str  # http://127.0.0.1:<port>
    pilot_token: str
    observer_token: str
    stderr_path: Path
    process: subprocess.Popen[str] | None = None  # to kill it the hard way

    @property
    def api(self) -> str:
        return f"{self.base_url}/api/v1"


@contextlib.contextmanager
def skyhelm_serve(
    log_dir: Path, *args: str, ready_timeout_s: float = 60.0, env: dict[str, str] | None = None
) -> Iterator[Served]:
    """Run `skyhelm serve --port 0 ARGS` with an observer token (and ``env`` added to the
    environment); yield once it printed its URL."""
    observer = secrets.token_urlsafe(16)
    command = [str(SKYHELM), "serve", "--port", "0", f"--observer-token={observer}"]
    command += ["--log-dir", str(log_dir), *args]
    stderr_path = log_dir / "serve.stderr.log"
    with stderr_path.open("w") as stderr:
        server = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=stderr, text=True,
            env=None if env is None else {**os.environ, **env},
        )
        try:
            line = _first_line(server, ready_timeout_s, stderr_path)
            base, _, token = line.removeprefix(READY_PREFIX).strip().partition("/?token=")
            yield Served(base, token, observer, stderr_path, server)
        finally:
            _stop(server)


def _first_line(server: subprocess.Popen[str], timeout_s: float, stderr_path: Path) -> str:
    assert server.stdout is not None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise AssertionError(
                f"skyhelm serve exited ({server.returncode}): {stderr_path.read_text()[-2000:]}"
            )
        readable, _, _ = select.select([server.stdout], [], [], 0.2)
        if readable:
            line = server.stdout.readline()
            if not line:  # stdout closed: it is exiting; report why
                server.wait(timeout=10)
                continue
            assert line.startswith(READY_PREFIX), f"unexpected first line: {line!r}"
            return line
    raise AssertionError(f"skyhelm serve printed no URL within {timeout_s} s")


def _stop(server: subprocess.Popen[str]) -> None:
    if server.poll() is None:
        server.send_signal(signal.SIGINT)
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
