"""The server's simulated vehicles spread over several `python -m sim` processes: every
vehicle reaches the server's links, and stopping the sim ends every process."""

from __future__ import annotations

from pathlib import Path

import pytest

from server.link import Link
from server.simproc import SimProcess
from tests.waiting import wait_for


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1][0]
    except FileNotFoundError:
        return False
    return state != "Z"


def _children(pid: int) -> list[int]:
    children: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        children += [int(child) for child in (task / "children").read_text().split()]
    return children


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads process children from /proc")
async def test_three_vehicles_in_two_processes_reach_the_server_and_stop_together() -> None:
    sim = SimProcess(count=3, processes=2, speed=2.0)
    instances = await sim.start()
    links: list[Link] = []
    try:
        assert [(i.instance, i.sysid) for i in instances] == [(0, 1), (1, 2), (2, 3)]
        assert sim.pid is not None
        vehicle_pids = _children(sim.pid)
        assert len(vehicle_pids) == 2
        for inst in instances:
            links.append(await Link.open(inst.url, log_dir=None))
        for link, inst in zip(links, instances, strict=True):
            await wait_for(lambda link=link, sysid=inst.sysid: sysid in link.vehicles, 30.0,
                           f"vehicle {inst.sysid}")
    finally:
        for link in links:
            await link.close()
        await sim.stop()
    assert not any(_alive(pid) for pid in vehicle_pids)
