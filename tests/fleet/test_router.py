"""`skyhelm router` as a site runs it: a process that prints where it listens; two sessions
in client mode, with scouting off, find each other only through it; SIGTERM stops it."""

from __future__ import annotations

import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from server.fleet.keys import FleetKeys
from server.fleet.session import ZenohOptions, open_session
from tests.waiting import wait_for_blocking

SKYHELM = Path(sys.executable).with_name("skyhelm")


def _lines_until_ready(router: subprocess.Popen[str], timeout_s: float) -> list[str]:
    """Its stdout up to the ready line (read on a thread: a blocking readline, no select on
    a buffered pipe)."""
    stdout = router.stdout
    assert stdout is not None
    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in stdout], daemon=True).start()
    seen: list[str] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            seen.append(lines.get(timeout=0.2).strip())
        except queue.Empty:
            assert router.poll() is None, f"router exited ({router.returncode}): {seen}"
            continue
        if seen[-1].startswith("SkyHelm router ready"):
            return seen
    raise AssertionError(f"the router printed no ready line within {timeout_s} s: {seen}")


@pytest.fixture(scope="module")
def router() -> Iterator[tuple[subprocess.Popen[str], str]]:
    process = subprocess.Popen(
        [str(SKYHELM), "router", "--listen", "tcp/127.0.0.1:0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        lines = _lines_until_ready(process, 30.0)
        listening = [line.removeprefix("SkyHelm router listening: ") for line in lines
                     if line.startswith("SkyHelm router listening: ")]
        assert len(listening) == 1
        assert listening[0].startswith("tcp/127.0.0.1:")
        assert not listening[0].endswith(":0"), "the router must say which port it took"
        yield process, listening[0]
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def _client(endpoint: str) -> zenoh.Session:
    return open_session(ZenohOptions(mode="client", connect=[endpoint], multicast_scouting=False))


def test_two_sessions_meet_through_the_router(
    router: tuple[subprocess.Popen[str], str],
) -> None:
    _, endpoint = router
    keys = FleetKeys("routertest")
    received: list[tuple[str, bytes]] = []
    with _client(endpoint) as fleet_side, _client(endpoint) as edge_side:
        # both are clients of the router, not peers of each other
        assert len(fleet_side.info.routers_zid()) == 1
        assert fleet_side.info.peers_zid() == []
        subscriber = fleet_side.declare_subscriber(
            keys.all_states("fast"),
            lambda sample: received.append((str(sample.key_expr), sample.payload.to_bytes())),
        )
        edge_side.declare_queryable(
            keys.api("edge-a"), lambda query: query.reply(query.key_expr, b'{"status": 200}')
        )
        state_key = keys.state("edge-a", 1, "fast")

        def delivered() -> bool:
            edge_side.put(state_key, b'{"seq": 1}')
            return bool(received)

        wait_for_blocking("a state put by one client reaching the other", delivered, 20.0, 0.2)
        assert received[0] == (state_key, b'{"seq": 1}')
        replies = list(fleet_side.get(keys.api("edge-a"), timeout=10.0))
        answers = [r.ok.payload.to_bytes() for r in replies if r.ok is not None]
        assert answers == [b'{"status": 200}']
        subscriber.undeclare()


def test_sigterm_stops_the_router(router: tuple[subprocess.Popen[str], str]) -> None:
    process, _ = router
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=20) == 0


def test_a_bad_endpoint_is_refused_with_a_message() -> None:
    done = subprocess.run(
        [str(SKYHELM), "router", "--listen", "nonsense/127.0.0.1:1"],
        capture_output=True, text=True, timeout=30,
    )
    assert done.returncode == 2
    assert done.stderr.startswith("skyhelm router: ")
