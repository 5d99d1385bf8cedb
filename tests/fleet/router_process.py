"""A Zenoh router for the process tests: `python -m tests.fleet.router_process ENDPOINT`.
Listens on ENDPOINT (loopback), multicast scouting off, the fleet's short lease; prints one
"router ready" line, runs until SIGINT/SIGTERM."""

from __future__ import annotations

import signal
import sys
import threading

from server.fleet.session import ZenohOptions, open_session


def main(endpoint: str) -> None:
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    session = open_session(
        ZenohOptions(mode="router", listen=[endpoint], multicast_scouting=False)
    )
    print(f"router ready {endpoint}", flush=True)
    stop.wait()
    session.close()


if __name__ == "__main__":
    main(sys.argv[1])
