"""The real MAVProxy connects to the simulated vehicle's GCS link and commands it."""

from __future__ import annotations

import asyncio
import contextlib
import shutil
import sys
from pathlib import Path

import pytest

from sim.process.runner import SimCluster
from tests.waiting import wait_for

pytestmark = pytest.mark.peers


def mavproxy_executable() -> str:
    candidate = Path(sys.prefix) / "bin" / "mavproxy.py"
    found = str(candidate) if candidate.exists() else shutil.which("mavproxy.py")
    if found is None:
        pytest.skip("MAVProxy not installed")
    return found


async def test_mavproxy_connects_shows_mode_arms_and_switches_to_rtl(tmp_path: Path) -> None:
    async with SimCluster(speed=2.0) as sim:
        await sim.wait_ready(timeout_s=10.0)
        inst = sim.instances[0]
        vehicle = inst.vehicle
        # --non-interactive reads no stdin, so the commands come with --cmd. MAVProxy runs
        # them at start-up: it talks first (udpout) so that they are not sent before it
        # has an address, and the sim answers whoever talked to it.
        proc = await asyncio.create_subprocess_exec(
            mavproxy_executable(), "--non-interactive",
            f"--master=udpout:127.0.0.1:{inst.gcs_local_port}",
            f"--state-basedir={tmp_path}", "--default-modules=mode,arm,cmdlong",
            "--target-system=1", "--target-component=1",
            "--cmd=arm throttle;long DO_SET_MODE 1 4 5",
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT, cwd=tmp_path,
        )
        lines: list[str] = []

        async def read_output() -> None:
            assert proc.stdout is not None
            while line := await proc.stdout.readline():
                lines.append(line.decode(errors="replace"))

        reader = asyncio.create_task(read_output())
        armed_seen = False

        def rtl_shown() -> bool:
            nonlocal armed_seen
            armed_seen = armed_seen or vehicle.armed
            return vehicle.mode_name == "AUTO_RTL" and "Mode RTL" in "".join(lines)

        try:
            await wait_for(rtl_shown, 30.0, "MAVProxy's switch to RTL")
            await wait_for(lambda: "ARMED" in "".join(lines), 10.0, "MAVProxy's ARMED")
        finally:
            proc.terminate()
            with contextlib.suppress(ProcessLookupError):
                await asyncio.wait_for(proc.wait(), 10.0)
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await reader
        output = "".join(lines)
        assert "Detected vehicle 1:1" in output
        assert "COMPONENT_ARM_DISARM: ACCEPTED" in output
        assert armed_seen
        assert "DO_SET_MODE: ACCEPTED" in output
        assert inst.gcs_link.counters.rx_messages > 0
        assert inst.api_link.counters.rx_messages == 0
