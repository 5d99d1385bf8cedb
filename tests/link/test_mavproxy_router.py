"""The same flight works whether SkyHelm talks to the vehicle directly or through MAVProxy.

sim ↔ MAVProxy (``--master`` to the sim, ``--out`` to us) ↔ Link: discover, arm, take off,
fly an offboard position setpoint to within 0.5 m, land.
"""

import asyncio
import contextlib
import math
import shutil
import sys
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from pymavlink import mavutil

from server.link import Link, PositionNed, Vehicle
from sim.process.runner import SimCluster, SimInstance
from tests.waiting import wait_for as _until

pytestmark = pytest.mark.peers

SIM_SPEED = 3.0
MAVPROXY = Path(sys.executable).parent / "mavproxy.py"
OFFBOARD_TOLERANCE_M = 0.5


def _distance_m(vehicle: Vehicle, target: PositionNed) -> float:
    position = vehicle.snapshot().position_ned
    if position is None:
        return math.inf
    return math.dist((position.north_m, position.east_m, position.down_m),
                     (target.north_m, target.east_m, target.down_m))


async def _fly_takeoff_offboard_land(link: Link, inst: SimInstance) -> None:
    vehicle = await asyncio.wait_for(link.subscribe_vehicles().get(), 10.0)
    assert vehicle.sysid == inst.sysid
    await _until(lambda: vehicle.snapshot().home is not None
                 and vehicle.snapshot().position_ned is not None
                 and vehicle.snapshot().ready_to_arm is True, 15.0, "home, position, ready")

    assert (await vehicle.arm()).ok
    assert (await vehicle.takeoff(3.0)).ok
    await _until(lambda: (vehicle.snapshot().global_position or _NO_ALT).alt_rel_m > 2.5,
                 20.0, "climb to 2.5 m")

    start = vehicle.snapshot().position_ned
    assert start is not None
    target = PositionNed(start.north_m + 3.0, start.east_m - 2.0, -4.0, yaw_deg=0.0)
    result = await vehicle.start_offboard(target)
    assert result.ok, result
    await _until(lambda: _distance_m(vehicle, target) < OFFBOARD_TOLERANCE_M, 20.0,
                 "offboard target reached")
    truth = inst.vehicle.truth.position_ned_m
    assert math.dist(truth, (target.north_m, target.east_m, target.down_m)) < 1.0

    assert (await vehicle.land()).ok
    await _until(lambda: vehicle.snapshot().landed_state == "ON_GROUND", 30.0, "landed")
    await _until(lambda: not vehicle.snapshot().armed, 15.0, "disarmed after landing")


def _recorded_sources(tlog: Path) -> set[tuple[int, str]]:
    conn = mavutil.mavlink_connection(str(tlog), dialect="development")
    seen = set()
    while (msg := conn.recv_match(blocking=False)) is not None:
        seen.add((msg.get_srcSystem(), msg.get_type()))
    conn.close()
    return seen


class _NoAltitude:
    alt_rel_m = -math.inf


_NO_ALT = _NoAltitude()


@contextlib.asynccontextmanager
async def _mavproxy(master_port: int, out_port: int, state_dir: Path) -> AsyncIterator[None]:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, str(MAVPROXY), "--non-interactive", "--nowait",
        f"--master=udpout:127.0.0.1:{master_port}", f"--out=udpout:127.0.0.1:{out_port}",
        f"--state-basedir={state_dir}", "--streamrate=-1", "--default-modules=",
        stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.DEVNULL, cwd=state_dir,
    )
    try:
        yield
    finally:
        proc.terminate()
        try:
            await asyncio.wait_for(proc.wait(), 5.0)
        except TimeoutError:
            proc.kill()
            await proc.wait()


async def test_flight_through_mavproxy_router_works_unchanged(tmp_path: Path) -> None:
    if not MAVPROXY.exists() and shutil.which("mavproxy.py") is None:
        pytest.skip("MAVProxy is not installed")
    async with SimCluster(airframe="quad", speed=SIM_SPEED) as sim:
        inst = sim.instances[0]
        link = await Link.open("udpin:127.0.0.1:0", log_dir=tmp_path)
        try:
            assert link.local_address is not None
            async with _mavproxy(inst.api_local_port, link.local_address[1], tmp_path):
                await _fly_takeoff_offboard_land(link, inst)
            stats = link.stats()
            assert stats.bad_frames == 0
            assert stats.frames_in > 100
        finally:
            await link.close()
    assert link.tlog_path is not None
    recorded = _recorded_sources(link.tlog_path)
    assert (inst.sysid, "HEARTBEAT") in recorded
    assert (255, "SET_POSITION_TARGET_LOCAL_NED") in recorded
    assert (255, "COMMAND_LONG") in recorded


async def test_same_flight_directly_against_the_vehicle(tmp_path: Path) -> None:
    async with SimCluster(airframe="quad", speed=SIM_SPEED) as sim:
        inst = sim.instances[0]
        link = await Link.open(f"udpout:127.0.0.1:{inst.api_local_port}")
        try:
            await _fly_takeoff_offboard_land(link, inst)
        finally:
            await link.close()

