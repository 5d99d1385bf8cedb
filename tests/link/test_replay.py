"""Replaying a .tlog through ``Link.open("tlog:...")``: a short flight of the simulated vehicle
is recorded once, then replayed faster than real time; the vehicle comes back with its
recorded identity and flight, our own recorded frames stay out, and nothing is ever sent."""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.tlog import TlogWriter, iter_tlog
from server.link.link import Link
from server.link.transports.replay import vehicle_frames
from server.link.vehicle import Vehicle
from tests.link.conftest import wait_for
from tests.waiting import holds_for

SIM_SPEED = 10.0
REPLAY_SPEED = 5.0
TAKEOFF_ALT_REL_M = 3.0
# Long enough in the air that the replay at REPLAY_SPEED shows the hover for ~0.1 s.
HOVER_S = 0.5
GCS_SYSID = 255
GCS_COMPID = 190


@dataclass(frozen=True)
class Recording:
    path: Path
    mav_type: str
    modes_seen: frozenset[str]
    max_alt_rel_m: float


def _alt_rel_m(vehicle: Vehicle) -> float:
    position = vehicle.snapshot().global_position
    return position.alt_rel_m if position is not None else math.nan


async def _record_flight(log_dir: Path) -> Recording:
    """Arm, take off, land and disarm the simulated quad with a recording link."""
    from sim.process.runner import SimCluster

    modes: set[str] = set()
    max_alt_rel_m = 0.0
    async with SimCluster(airframe="quad", count=1, speed=SIM_SPEED) as sim:
        url = f"udpout:127.0.0.1:{sim.instances[0].api_local_port}"
        async with await Link.open(url, log_dir=log_dir, name="flight") as link:
            await wait_for(lambda: 1 in link.vehicles, 10.0, "discovery")
            vehicle = link.vehicles[1]
            assert isinstance(vehicle, Vehicle)
            # home comes with the first HEARTBEAT (as on PX4); arming waits for the checks
            await wait_for(lambda: vehicle.snapshot().home is not None
                           and vehicle.snapshot().ready_to_arm is True, 10.0, "home, ready")

            async def watch() -> None:
                nonlocal max_alt_rel_m
                async for state in vehicle.subscribe():  # every change of the vehicle's state
                    modes.add(state.mode)
                    alt_rel_m = _alt_rel_m(vehicle)
                    if not math.isnan(alt_rel_m):
                        max_alt_rel_m = max(max_alt_rel_m, alt_rel_m)

            watcher = asyncio.create_task(watch())
            try:
                assert (await vehicle.arm()).ok
                assert (await vehicle.takeoff(TAKEOFF_ALT_REL_M)).ok
                await wait_for(lambda: vehicle.snapshot().landed_state == "IN_AIR", 8.0,
                               "takeoff")  # fmt: skip
                # PX4 switches to Hold once the takeoff altitude is reached
                await wait_for(lambda: vehicle.snapshot().mode == "HOLD", 8.0, "takeoff done")
                # not a wait: the recorded flight hovers this long (the replay plays the
                # recording's wall-clock timestamps back, so the hover has to last in wall time)
                await asyncio.sleep(HOVER_S)
                assert (await vehicle.land()).ok
                await wait_for(lambda: not vehicle.snapshot().armed, 10.0, "landed, disarmed")
            finally:
                watcher.cancel()
            mav_type = vehicle.snapshot().mav_type
            path = link.tlog_path
    assert path is not None
    return Recording(path, mav_type, frozenset(modes), max_alt_rel_m)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Recording:
    # One flight for the whole module, on its own loop: recording is the slow part.
    return asyncio.run(_record_flight(tmp_path_factory.mktemp("tlogs")))


def _tlog_url(recording: Recording, query: str = f"speed={REPLAY_SPEED:g}") -> str:
    return f"tlog:{recording.path}?{query}"


async def test_replayed_vehicle_has_the_recorded_identity_and_flies_the_recorded_flight(
    recording: Recording,
) -> None:
    seen: list[tuple[bool, str, str, float]] = []
    async with await Link.open(_tlog_url(recording), log_dir=None) as link:
        await wait_for(lambda: 1 in link.vehicles, 5.0, "discovery from the recording")
        vehicle = link.vehicles[1]
        assert isinstance(vehicle, Vehicle)
        assert list(link.vehicles) == [1]
        assert vehicle.snapshot().mav_type == recording.mav_type

        def landed_after_flying() -> bool:
            state = vehicle.snapshot()
            seen.append((state.armed, state.landed_state, state.mode, _alt_rel_m(vehicle)))
            was_in_air = any(armed and landed == "IN_AIR" for armed, landed, _, _ in seen)
            return was_in_air and not state.armed and state.landed_state == "ON_GROUND"

        await wait_for(landed_after_flying, 10.0, "armed in the air, then landed")

    assert {"TAKEOFF", "LAND"} <= {mode for _, _, mode, _ in seen} <= recording.modes_seen
    max_alt_rel_m = max(alt for _, _, _, alt in seen if not math.isnan(alt))
    assert max_alt_rel_m == pytest.approx(recording.max_alt_rel_m, abs=0.5)


async def test_our_own_recorded_gcs_frames_are_not_replayed(recording: Recording) -> None:
    sources = [(frame[5], frame[6]) for _, frame in iter_tlog(recording.path)]
    assert (GCS_SYSID, GCS_COMPID) in sources, "the recording holds what the GCS sent"
    replayed = vehicle_frames(recording.path)
    assert {frame[5] for _, frame in replayed.frames} == {1}
    assert replayed.frames_skipped == sources.count((GCS_SYSID, GCS_COMPID))

    async with await Link.open(_tlog_url(recording, "speed=50"), log_dir=None) as link:
        await wait_for(lambda: link.stats().frames_in == len(replayed.frames), 10.0,
                       "the whole vehicle side")  # fmt: skip
        await holds_for(lambda: link.stats().frames_in == len(replayed.frames), 0.1,
                        "nothing replayed beyond the vehicle side")  # fmt: skip


def _frame(msg: mavlink.MAVLink_message, sysid: int, compid: int) -> bytes:
    return bytes(msg.pack(mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)))


async def test_only_systems_that_announce_a_vehicle_are_replayed(tmp_path: Path) -> None:
    def heartbeat(mav_type: int, autopilot: int) -> mavlink.MAVLink_message:
        return mavlink.MAVLink_heartbeat_message(mav_type, autopilot, 0, 0, 0, 3)

    status = mavlink.MAVLink_system_time_message(0, 0)
    autopilot = heartbeat(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4)
    companion = heartbeat(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID)
    gcs = heartbeat(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID)
    frames = [
        _frame(autopilot, 1, 1),
        _frame(companion, 1, 191),
        _frame(status, 1, 191),  # a companion on the vehicle: the vehicle side
        _frame(gcs, 1, 190),
        _frame(status, 1, 190),  # a GCS that borrowed the vehicle's sysid
        _frame(gcs, 254, 1),
        _frame(status, 254, 1),  # another ground station
        _frame(status, 42, 1),  # a system that never said it was a vehicle
    ]
    writer = TlogWriter(tmp_path / "mixed.tlog")
    for index, frame in enumerate(frames):
        writer.record(frame, unix_time_s=1000.0 + index * 0.01)
    await writer.close()

    replayed = vehicle_frames(writer.path)

    assert [frame for _, frame in replayed.frames] == frames[:3]
    assert replayed.vehicle_systems == {1}
    assert replayed.frames_skipped == 5


async def test_writes_are_dropped_and_counted(recording: Recording) -> None:
    async with await Link.open(_tlog_url(recording), log_dir=None) as link:
        await wait_for(lambda: 1 in link.vehicles, 5.0, "discovery")
        dropped_before = link.frames_dropped_out
        link.send_gcs_heartbeat()
        link.send(link.mav.command_long_encode(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM,
                                               0, 1, 0, 0, 0, 0, 0, 0))  # fmt: skip

        assert link.frames_dropped_out == dropped_before + 2
        assert link.stats().frames_out == 0


async def test_vehicle_is_lost_at_the_end_of_the_recording(recording: Recording) -> None:
    url = _tlog_url(recording, "speed=50")
    async with await Link.open(url, log_dir=None, heartbeat_timeout_s=0.5) as link:
        await wait_for(lambda: 1 in link.vehicles, 5.0, "discovery")
        vehicle = link.vehicles[1]
        await wait_for(lambda: not vehicle.connected, 10.0, "lost after the last heartbeat")
        assert not link.stats().connected


async def test_a_looping_replay_starts_over_and_keeps_the_vehicle(recording: Recording) -> None:
    one_pass = len(vehicle_frames(recording.path).frames)
    url = _tlog_url(recording, "speed=50&loop=1")
    async with await Link.open(url, log_dir=None, heartbeat_timeout_s=0.5) as link:
        await wait_for(lambda: link.stats().frames_in > 2 * one_pass, 10.0, "a second pass")
        assert link.vehicles[1].connected


async def test_a_missing_recording_fails_to_open(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        await Link.open(f"tlog:{tmp_path / 'none.tlog'}", log_dir=None)
