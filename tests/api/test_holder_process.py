"""Proving which process holds a REST lease (/proc): believed only for the process that owns
the request's connection over loopback, and gone once it exits (reaped or a zombie)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from collections.abc import Iterator

import pytest

from server.control.holder_process import verified_holder
from server.control.lease import LeaseEnd, LeaseManager
from tests.waiting import wait_for_blocking

pytestmark = pytest.mark.skipif(not os.path.exists("/proc/self/fd"), reason="needs Linux /proc")

# connects to the port given, prints its own end's port, then waits for stdin to close
_CLIENT = """
import socket, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
print(s.getsockname()[1], flush=True)
sys.stdin.read()
"""


@pytest.fixture
def listener() -> Iterator[socket.socket]:
    with socket.create_server(("127.0.0.1", 0)) as server:
        yield server


def _connected_child(listener: socket.socket) -> tuple[subprocess.Popen[str], int]:
    port = listener.getsockname()[1]
    child = subprocess.Popen(
        [sys.executable, "-c", _CLIENT, str(port)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert child.stdout is not None
    client_port = int(child.stdout.readline())
    return child, client_port


def test_the_process_owning_the_connection_is_proved_and_then_gone(
    listener: socket.socket,
) -> None:
    child, client_port = _connected_child(listener)
    try:
        holder = verified_holder(child.pid, "127.0.0.1", client_port)
        assert holder is not None
        assert holder.pid == child.pid
        assert not holder.gone()
        child.kill()
        child.wait()
        assert holder.gone()
    finally:
        child.kill()
        child.wait()


def test_a_killed_process_not_yet_reaped_is_gone(listener: socket.socket) -> None:
    child, client_port = _connected_child(listener)
    holder = verified_holder(child.pid, "127.0.0.1", client_port)
    assert holder is not None
    child.kill()
    try:
        # a zombie until its parent waits for it: /proc still lists it
        wait_for_blocking("the killed process seen gone", holder.gone, 5.0)
    finally:
        child.wait()


def test_a_process_that_does_not_own_the_connection_is_not_believed(
    listener: socket.socket,
) -> None:
    child, client_port = _connected_child(listener)
    try:
        assert verified_holder(os.getpid(), "127.0.0.1", client_port) is None  # not ours
        assert verified_holder(child.pid, "127.0.0.1", client_port + 1) is None  # wrong port
        assert verified_holder(child.pid, "10.1.2.3", client_port) is None  # not loopback
        assert verified_holder(child.pid, "testclient", client_port) is None  # not an address
    finally:
        child.kill()
        child.wait()


def test_a_lease_ends_as_gone_when_its_process_exits_and_not_while_it_lives(
    listener: socket.socket,
) -> None:
    ended: list[str] = []
    leases = LeaseManager(120.0, clock=lambda: 0.0)
    leases.add_listener(lambda _lease, what: ended.append(what))
    child, client_port = _connected_child(listener)
    try:
        lease = leases.acquire(1, "pilot · script", session="rest")
        lease.process = verified_holder(child.pid, "127.0.0.1", client_port)
        assert lease.process is not None
        leases.expire_due()
        assert leases.current(1) is lease  # alive and quiet: held until its TTL
        child.kill()
        wait_for_blocking("the process seen gone", lease.process.gone, 5.0)
        assert leases.expire_due() == [lease]
    finally:
        child.kill()
        child.wait()
    assert leases.current(1) is None
    assert lease.end is LeaseEnd.GONE
    assert ended == ["acquired", "gone"]
    assert leases.last_ended(1) is lease
    assert leases.acquire(1, "pilot · next", session="rest").holder == "pilot · next"
