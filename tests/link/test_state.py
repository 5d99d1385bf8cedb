"""Vehicle state from telemetry: snapshot fields, STATUSTEXT reassembly, RTL phase, events,
latest-wins subscriptions."""

from __future__ import annotations

import asyncio
import dataclasses
import json
import math
import time

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.statustext import StatusTextAssembler
from server.link.core.state import (
    WAKE_BATCH,
    BatteryState,
    GpsState,
    PositionNedState,
    SubscriptionHub,
    VehicleState,
)
from tests.link.conftest import ScriptedSession, drain, wait_for

HOLD = 0x3040000
RTL = 0x5040000
OFFBOARD = 0x60000


def _telemetry() -> list[mavlink.MAVLink_message]:
    return [
        mavlink.MAVLink_local_position_ned_message(0, 1.0, 2.0, -3.0, 0.5, 0.0, -0.1),
        mavlink.MAVLink_global_position_int_message(0, 473977420, 85455940, 492400, 3000,
                                                    50, 0, -10, 9000),
        mavlink.MAVLink_attitude_message(0, 0.1, -0.05, math.pi / 2, 0.0, 0.0, 0.2),
        mavlink.MAVLink_extended_sys_state_message(3, 2),
        mavlink.MAVLink_home_position_message(473977420, 85455940, 489400, 0.0, 0.0, 0.0,
                                              [1, 0, 0, 0], 0, 0, 0),
        mavlink.MAVLink_gps_global_origin_message(473977420, 85455940, 489400),
        mavlink.MAVLink_sys_status_message(0, 0, 0, 0, 16200, 1250, 87, 0, 0, 0, 0, 0, 0),
        mavlink.MAVLink_gps_raw_int_message(0, 3, 0, 0, 0, 90, 65535, 0, 0, 12),
        mavlink.MAVLink_vfr_hud_message(0.4, 0.5, 90, 40, 492.4, 0.1),
        mavlink.MAVLink_servo_output_raw_message(0, 0, 1500, 1600, 1000, 2000, 0, 0, 0, 0),
        mavlink.MAVLink_position_target_local_ned_message(0, 1, 2552, 1, 2, -3, 0, 0, 0,
                                                          0, 0, 0, 0, 0),
    ]  # fmt: skip


async def test_snapshot_carries_telemetry_in_named_units(scripted: ScriptedSession) -> None:
    for msg in _telemetry():
        scripted.peer.send(msg)
    await wait_for(lambda: scripted.vehicle.snapshot().target_ned is not None)

    state = scripted.vehicle.snapshot()
    assert state.mav_type == "QUADROTOR"
    assert state.autopilot == "PX4"
    assert state.mode == "HOLD"
    assert not state.armed
    assert state.position_ned == PositionNedState(1.0, 2.0, -3.0)
    assert state.global_position is not None
    assert state.global_position.alt_rel_m == pytest.approx(3.0)
    assert state.attitude is not None
    assert state.attitude.yaw_deg == pytest.approx(90.0)
    assert (state.landed_state, state.vtol_state) == ("IN_AIR", "MC")
    assert state.home is not None
    assert state.home.alt_amsl_m == pytest.approx(489.4)
    assert state.origin is not None
    assert state.origin.lat_deg == pytest.approx(47.397742)
    assert state.battery == BatteryState(pytest.approx(16.2), 12.5, 87.0)  # type: ignore[arg-type]
    assert state.gps == GpsState("3D_FIX", 12, pytest.approx(0.9))  # type: ignore[arg-type]
    assert state.actuator_outputs == pytest.approx((0.5, 0.6, 0.0, 1.0))
    assert state.heading_deg == 90.0
    assert state.ground_speed_m_s == pytest.approx(0.5)
    assert state.link.frames_in > 0
    json.dumps(dataclasses.asdict(state))  # JSON-able as the API needs it


async def test_current_mode_gives_mode_and_user_intended_mode_before_heartbeat(
    scripted: ScriptedSession,
) -> None:
    # PX4 failsafe: current POSCTL, the user still wants OFFBOARD; HEARTBEAT says HOLD
    scripted.peer.send(mavlink.MAVLink_current_mode_message(0, 0x30000, OFFBOARD))
    await wait_for(lambda: scripted.vehicle.snapshot().user_mode == "OFFBOARD")
    scripted.peer.heartbeat()
    await scripted.vehicle_heard_all()

    state = scripted.vehicle.snapshot()
    assert (state.mode, state.user_mode) == ("POSCTL", "OFFBOARD")


async def test_chunked_statustext_is_reassembled(scripted: ScriptedSession) -> None:
    long_text = "Preflight Fail: " + "x" * 60 + " end"
    chunks = [long_text[i : i + 50] for i in range(0, len(long_text), 50)]
    for seq, chunk in enumerate(chunks):
        scripted.peer.send(mavlink.MAVLink_statustext_message(
            mavlink.MAV_SEVERITY_CRITICAL, chunk.encode(), 7, seq))  # fmt: skip
    await wait_for(lambda: bool(scripted.vehicle.snapshot().statustext))

    (text,) = scripted.vehicle.snapshot().statustext
    assert text.text == long_text
    assert text.severity == "CRITICAL"


def test_statustext_with_a_lost_last_chunk_is_released_after_the_timeout() -> None:
    now = [0.0]
    assembler = StatusTextAssembler(lambda: now[0], timeout_s=1.0)
    assert assembler.feed(4, "a" * 50, 3, 0) == []
    now[0] = 1.5

    assert assembler.feed(6, "next", 0, 0) == [(4, "a" * 50), (6, "next")]


async def test_rtl_phase_follows_the_vehicle_rtl_statustexts(scripted: ScriptedSession) -> None:
    peer = scripted.peer
    peer.custom_mode = RTL
    peer.heartbeat()
    peer.send(
        mavlink.MAVLink_statustext_message(
            6, b"RTL: start return at 520 m (30 m above destination)"
        )
    )
    await wait_for(lambda: scripted.vehicle.snapshot().rtl_phase == "RETURNING")
    peer.send(mavlink.MAVLink_statustext_message(6, b"RTL: land at destination"))
    await wait_for(lambda: scripted.vehicle.snapshot().rtl_phase == "LANDING")
    # PX4 v1.16 says nothing more: touching down (ON_GROUND) ends the return
    peer.send(mavlink.MAVLink_extended_sys_state_message(0, mavlink.MAV_LANDED_STATE_ON_GROUND))
    await wait_for(lambda: scripted.vehicle.snapshot().rtl_phase == "LANDED")
    # disarmed, PX4 goes back to the mode chosen before RTL
    peer.custom_mode = HOLD
    peer.heartbeat()

    await wait_for(lambda: scripted.vehicle.snapshot().rtl_phase is None)


async def test_mode_and_armed_changes_become_events(scripted: ScriptedSession) -> None:
    events = scripted.vehicle.subscribe_events()
    scripted.peer.base_mode = 1 | 128
    scripted.peer.custom_mode = OFFBOARD
    scripted.peer.heartbeat()
    await wait_for(lambda: scripted.vehicle.snapshot().armed)

    kinds = {e.kind: e.data for e in drain(events)}
    assert kinds["mode"] == {"mode": "OFFBOARD", "previous": "HOLD"}
    assert kinds["armed"] == {"armed": True}


async def test_event_queue_drops_oldest_when_full(scripted: ScriptedSession) -> None:
    events = scripted.vehicle.subscribe_events(maxsize=3)
    for i in range(5):
        scripted.vehicle.publish_event("lease", {"n": i})

    assert [e.data["n"] for e in drain(events)] == [2, 3, 4]


async def test_subscription_is_latest_wins(scripted: ScriptedSession) -> None:
    sub = scripted.vehicle.subscribe()
    await asyncio.wait_for(anext(sub), 1.0)  # the state at subscription
    for i in range(20):
        scripted.peer.send(mavlink.MAVLink_local_position_ned_message(0, float(i), 0, 0, 0, 0, 0))
    await wait_for(lambda: _north_m(scripted) == 19.0)

    latest = await asyncio.wait_for(anext(sub), 1.0)
    assert latest.position_ned is not None
    assert latest.position_ned.north_m == 19.0
    with pytest.raises(TimeoutError):  # nothing is queued behind it
        await asyncio.wait_for(anext(sub), 0.1)
    sub.close()


async def test_rate_limited_subscription_holds_changes_until_its_interval_is_up(
    scripted: ScriptedSession,
) -> None:
    interval_s = 0.3
    sub = scripted.vehicle.subscribe(min_interval_s=interval_s)
    assert await asyncio.wait_for(sub.changed(), 1.0)  # the state at subscription, at once
    read_s = time.monotonic()
    version = scripted.vehicle.state_version
    scripted.peer.send(mavlink.MAVLink_local_position_ned_message(0, 7.0, 0, 0, 0, 0, 0))
    await wait_for(lambda: _north_m(scripted) == 7.0)
    assert scripted.vehicle.state_version > version

    # held back, not dropped: it comes once the interval is up, with nothing newer needed
    assert await asyncio.wait_for(sub.changed(), 2.0)
    assert time.monotonic() - read_s >= interval_s
    sub.close()
    assert not await asyncio.wait_for(sub.changed(), 1.0)


async def test_a_change_wakes_many_readers_in_batches_with_other_callbacks_between() -> None:
    def no_snapshot() -> VehicleState:
        raise AssertionError("waking readers needs no snapshot")

    hub = SubscriptionHub(no_snapshot)
    subs = [hub.subscribe() for _ in range(3 * WAKE_BATCH)]
    for sub in subs:
        assert await sub.changed()  # the state at subscription
    still_queued: list[int] = []

    hub.notify()
    asyncio.get_running_loop().call_soon(
        lambda: still_queued.append(sum(sub.queued for sub in subs))
    )
    assert sum(sub.queued for sub in subs) == 2 * WAKE_BATCH
    woken = await asyncio.wait_for(asyncio.gather(*(sub.changed() for sub in subs)), 1.0)

    assert all(woken)
    # the callback queued right after the change ran while one batch was still waiting
    assert still_queued == [WAKE_BATCH]


async def test_connection_loss_and_return_are_events(scripted: ScriptedSession) -> None:
    events = scripted.vehicle.subscribe_events()
    scripted.vehicle.set_connected(False)
    scripted.vehicle.set_connected(True)

    assert [e.data["connected"] for e in drain(events) if e.kind == "connection"] == [
        False, True
    ]


def _north_m(session: ScriptedSession) -> float | None:
    position = session.vehicle.snapshot().position_ned
    return None if position is None else position.north_m
