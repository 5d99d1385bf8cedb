"""The client gives its lease back however the script ends: leaving its `with` block by an
exception, SIGTERM, or an interpreter exiting with the lease still held (no `with`)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from skyhelm_client import SkyHelm
from tests.client.conftest import pilot_url
from tests.serve_process import Served
from tests.waiting import wait_for_blocking

# takes the lease, says so, then waits (for a signal) or ends (with the lease held)
# A script's end: an interpreter's exit and a release that may wait 2 s for each of connect,
# write and read; seen over 10 s on a machine loaded to 5 (two busy loops beside the suite).
SCRIPT_END_S = 30
_SCRIPT = """
import sys, time
from skyhelm_client import SkyHelm
sky = SkyHelm(sys.argv[1])
print(sky.acquire(client_name="script").holder, flush=True)
if sys.argv[2] == "wait":
    time.sleep(60)
"""


def _last_end(sky: SkyHelm) -> dict[str, object]:
    control = wait_for_blocking(
        "control free", lambda: (c := sky.control_status())["holder"] is None and c, 5.0
    )
    last_end: dict[str, object] = control["last_end"]
    return last_end


def _script(served: Served, mode: str) -> subprocess.Popen[str]:
    process = subprocess.Popen(
        [sys.executable, "-c", _SCRIPT, pilot_url(served), mode],
        stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    assert process.stdout is not None
    assert process.stdout.readline().strip() == "pilot · script"
    return process


def _fail_while_holding(served: Served, watcher: SkyHelm) -> None:
    with SkyHelm(pilot_url(served)) as sky:
        sky.acquire(client_name="with block")
        assert watcher.control_status()["holder_pid"] == os.getpid()  # proved, watched
        raise RuntimeError("the script fails")


def test_the_lease_is_given_back_however_the_script_ends(served: Served) -> None:
    with SkyHelm(pilot_url(served)) as watcher:
        with pytest.raises(RuntimeError):
            _fail_while_holding(served, watcher)
        assert _last_end(watcher)["end"] == "released"

        waiting = _script(served, "wait")
        waiting.send_signal(signal.SIGTERM)
        assert waiting.wait(timeout=SCRIPT_END_S) == 128 + signal.SIGTERM
        ended = _last_end(watcher)
        assert ended == {**ended, "holder": "pilot · script", "end": "released"}

        ending = _script(served, "end")  # no with block: atexit gives it back
        assert ending.wait(timeout=SCRIPT_END_S) == 0
        ended = _last_end(watcher)
        assert ended == {**ended, "holder": "pilot · script", "end": "released"}
