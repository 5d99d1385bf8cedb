"""Link loss without a network fault: when a vehicle counts as lost (silence while it
streams, the heartbeat otherwise, a stalled loop forgiven), what the state shows while it
is lost and after it is back, the stream stopped for good, the report on the return, and
a reboot noticed by the boot clock."""

from __future__ import annotations

import asyncio

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.setpoints import PositionNed
from server.link.core.events import VehicleEvent
from server.link.core.liveness import Liveness
from server.link.plugins.telemetry import MODE_WITHHELD
from server.link.stream.stream_process import REPORT_PERIOD_S
from tests.link.conftest import ScriptedSession, drain, wait_for
from tests.waiting import holds_for

OFFBOARD = 0x60000
POSCTL = 0x30000
ARMED_CUSTOM = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED


def _streamed(liveness: Liveness, sysid: int, from_s: float, to_s: float, rate_hz: float) -> None:
    """Frames at rate_hz from from_s to to_s, a HEARTBEAT among them every second."""
    for i in range(round((to_s - from_s) * rate_hz) + 1):
        t = from_s + i / rate_hz
        if i % round(rate_hz) == 0:
            liveness.heartbeat(sysid, t)
        liveness.frame(sysid, t)


def test_a_streaming_vehicle_is_lost_after_the_silence_bound() -> None:
    liveness = Liveness(heartbeat_timeout_s=5.0, silence_timeout_s=1.0)
    _streamed(liveness, 1, 0.0, 2.5, rate_hz=50.0)
    last_s = 2.5
    assert liveness.silent_for(1, last_s + 0.9) is None
    assert liveness.silent_for(1, last_s + 1.1) == "nothing heard for 1.0 s"


def test_a_vehicle_sending_only_heartbeats_is_judged_by_the_heartbeat_timeout() -> None:
    liveness = Liveness(heartbeat_timeout_s=5.0, silence_timeout_s=1.0)
    for second in range(4):
        liveness.heartbeat(1, float(second))
        liveness.frame(1, float(second))
    assert liveness.silent_for(1, 3.0 + 4.9) is None
    assert liveness.silent_for(1, 3.0 + 5.1) == "nothing heard for 5.0 s"


def test_frames_before_the_first_heartbeat_tell_that_it_streams() -> None:
    # PX4 starts its streams on a link at once and sends its HEARTBEAT within the second:
    # a link cut just after that HEARTBEAT is still judged by the silence bound
    liveness = Liveness(heartbeat_timeout_s=5.0, silence_timeout_s=1.0)
    for i in range(40):
        liveness.frame(1, i / 50.0)
    assert not liveness.known(1)
    liveness.heartbeat(1, 0.8)
    liveness.frame(1, 0.8)
    assert liveness.quality(1, 0.8).lost_after_s == 1.0
    assert liveness.silent_for(1, 0.8 + 1.1) == "nothing heard for 1.0 s"
    # and frames long before it give its rate at once
    late = Liveness(heartbeat_timeout_s=5.0, silence_timeout_s=1.0)
    for i in range(20):
        late.frame(2, i * 0.2)  # 5 Hz for 4 s: not streaming
    late.heartbeat(2, 4.0)
    late.frame(2, 4.0)
    assert late.quality(2, 4.0).rate_hz == 20 / 4.0
    assert late.silent_for(2, 4.0 + 4.9) is None


def test_missing_heartbeats_of_a_streaming_vehicle_are_a_warning_never_a_verdict() -> None:
    liveness = Liveness(heartbeat_timeout_s=5.0, silence_timeout_s=1.0)
    _streamed(liveness, 1, 0.0, 2.0, rate_hz=50.0)
    for i in range(1, 500):  # 10 s more of frames, none of them a HEARTBEAT
        t = 2.0 + i / 50.0
        liveness.frame(1, t)
        assert liveness.silent_for(1, t + 0.05) is None
    quality = liveness.quality(1, 12.0)
    assert quality.degraded
    assert quality.causes == ("heartbeat",)
    assert quality.lost_after_s == 1.0


def test_loss_from_sequence_gaps_warns_with_hysteresis_and_silence_warns_first() -> None:
    liveness = Liveness(heartbeat_timeout_s=5.0, silence_timeout_s=1.0)
    t = 0.0
    for i in range(300):  # 6 s at 50 Hz, one frame in five missing: 20 %
        t = i / 50.0
        if i % 50 == 0:
            liveness.heartbeat(1, t)
        liveness.frame(1, t, missing=1 if i % 4 == 0 else 0)
    warned = liveness.quality(1, t)
    assert warned.degraded
    assert warned.causes == ("loss_in",)
    assert warned.loss_in_pct is not None
    assert 15.0 <= warned.loss_in_pct <= 25.0
    for i in range(300, 600):  # 6 s with 1 in 8 missing (12.5 %): above the clearing 10 %
        t = i / 50.0
        if i % 50 == 0:
            liveness.heartbeat(1, t)
        liveness.frame(1, t, missing=1 if i % 7 == 0 else 0)
    assert liveness.quality(1, t).causes == ("loss_in",)
    for i in range(600, 900):  # 6 s without loss: clear
        t = i / 50.0
        if i % 50 == 0:
            liveness.heartbeat(1, t)
        liveness.frame(1, t)
    assert not liveness.quality(1, t).degraded
    assert liveness.quality(1, t + 0.4).causes == ()
    assert liveness.quality(1, t + 0.6).causes == ("silence",)  # the warning before...
    assert liveness.silent_for(1, t + 0.6) is None
    assert liveness.silent_for(1, t + 1.1) is not None  # ...the verdict


def test_the_vehicles_own_count_of_our_lost_frames_is_the_outbound_loss() -> None:
    liveness = Liveness(heartbeat_timeout_s=5.0, silence_timeout_s=1.0)
    _streamed(liveness, 1, 0.0, 2.0, rate_hz=50.0)
    liveness.node_status(1, 1.0, received=1000, lost=10)
    liveness.node_status(1, 2.0, received=1080, lost=30)
    quality = liveness.quality(1, 2.0)
    assert quality.loss_out_pct == 20.0
    assert quality.causes == ("loss_out",)
    liveness.node_status(1, 3.0, received=5, lost=0)  # the vehicle restarted its counts
    assert liveness.quality(1, 3.0).loss_out_pct is None


def test_a_stalled_loop_is_not_silence() -> None:
    liveness = Liveness(heartbeat_timeout_s=5.0, silence_timeout_s=1.0)
    _streamed(liveness, 1, 0.0, 2.0, rate_hz=50.0)
    liveness.forgive(1.5)  # the loop stood still: nothing could have been read
    assert liveness.silent_for(1, 2.0 + 1.6) is None
    assert liveness.silent_for(1, 2.0 + 1.5 + 1.1) is not None


def _telemetry(session: ScriptedSession, custom_mode: int, down_m: float) -> None:
    peer = session.peer
    peer.base_mode = ARMED_CUSTOM
    peer.custom_mode = custom_mode
    peer.send(mavlink.MAVLink_current_mode_message(0, custom_mode, OFFBOARD))
    peer.heartbeat()
    peer.send(mavlink.MAVLink_local_position_ned_message(0, 0.0, 0.0, down_m, 0, 0, 0))
    peer.send(mavlink.MAVLink_global_position_int_message(
        0, 473977420, 85455940, 489400 - int(down_m * 1000), int(-down_m * 1000), 0, 0, 0, 0))
    peer.send(mavlink.MAVLink_attitude_message(0, 0, 0, 0, 0, 0, 0))


async def test_loss_stops_the_stream_marks_state_stale_and_the_return_is_reported(
    scripted: ScriptedSession,
) -> None:
    vehicle = scripted.vehicle
    _telemetry(scripted, OFFBOARD, -10.0)
    await scripted.vehicle_heard_all()
    await vehicle.set_setpoint(PositionNed(0.0, 0.0, -10.0))
    assert vehicle.streamer_active
    events = vehicle.subscribe_events()

    vehicle.set_connected(False, "nothing heard for 1.0 s")
    lost = vehicle.snapshot()
    assert not lost.connected
    assert not vehicle.streamer_active
    assert {"mode", "armed", "position_ned", "attitude"} <= set(lost.stale)
    assert lost.mode == "OFFBOARD"  # the last known one, marked stale

    vehicle.set_connected(True)
    back = vehicle.snapshot()
    assert back.mode == MODE_WITHHELD  # not the mode from before the cut
    assert back.user_mode is None
    assert "position_ned" in back.stale
    _telemetry(scripted, POSCTL, -9.8)
    await scripted.vehicle_heard_all()
    fresh = vehicle.snapshot()
    assert fresh.mode == "POSCTL"
    assert fresh.user_mode == "OFFBOARD"
    assert not {"mode", "armed", "position_ned", "global_position", "attitude"} & set(fresh.stale)

    seen: list[VehicleEvent] = []
    await wait_for(lambda: seen.extend(drain(events)) or any(
        e.kind == "link_restored" for e in seen), 3.0, "the report")
    (report,) = [e.data for e in seen if e.kind == "link_restored"]
    assert report["mode_before"] == "OFFBOARD"
    assert report["mode_after"] == "POSCTL"
    assert report["failsafe"] is True
    assert "vehicle left OFFBOARD for POSCTL (failsafe), altitude 10.0 -> 9.8 m" in str(
        report["text"])
    stream_reasons = [e.data.get("reason") for e in seen if e.kind == "stream"]
    assert stream_reasons[0] == "link lost"
    assert "link back" in str(stream_reasons[-1])
    assert [e.data["connected"] for e in seen if e.kind == "connection"] == [False, True]


async def test_the_stream_stays_stopped_after_the_return_until_a_setpoint(
    scripted: ScriptedSession,
) -> None:
    vehicle = scripted.vehicle
    _telemetry(scripted, OFFBOARD, -5.0)
    await scripted.vehicle_heard_all()
    await vehicle.set_setpoint(PositionNed(0.0, 0.0, -5.0))
    vehicle.set_connected(False, "test")
    vehicle.set_connected(True)
    assert not vehicle.streamer_active
    # the sender process reports what it wrote every REPORT_PERIOD_S: the count settles
    await asyncio.sleep(3 * REPORT_PERIOD_S)
    sent = vehicle.stream_stats().sent
    await holds_for(lambda: vehicle.stream_stats().sent == sent and not vehicle.streamer_active,
                    0.3, "nothing streamed after the return")
    await vehicle.set_setpoint(PositionNed(0.0, 0.0, -5.0))
    assert vehicle.streamer_active


async def test_a_boot_clock_going_back_is_a_reboot(scripted: ScriptedSession) -> None:
    vehicle = scripted.vehicle
    peer = scripted.peer
    _telemetry(scripted, OFFBOARD, -5.0)
    peer.send(mavlink.MAVLink_attitude_message(60_000, 0, 0, 0, 0, 0, 0))
    peer.send(mavlink.MAVLink_home_position_message(
        473977420, 85455940, 489400, 0.0, 0.0, 0.0, [1, 0, 0, 0], 0, 0, 0))
    await scripted.vehicle_heard_all()
    await vehicle.set_setpoint(PositionNed(0.0, 0.0, -5.0))
    assert vehicle.snapshot().home is not None
    events = vehicle.subscribe_events()

    peer.send(mavlink.MAVLink_attitude_message(59_500, 0, 0, 0, 0, 0, 0))  # reordered: no
    await scripted.vehicle_heard_all()
    assert not [e for e in drain(events) if e.kind == "reboot"]
    peer.send(mavlink.MAVLink_attitude_message(400, 0, 0, 0, 0, 0, 0))
    await scripted.vehicle_heard_all()

    told = drain(events)
    (reboot,) = [e for e in told if e.kind == "reboot"]
    assert "from 60.0 s to 0.4 s" in str(reboot.data["reason"])
    state = vehicle.snapshot()
    assert state.home is None  # a rebooted vehicle sets its home again
    assert state.mode == MODE_WITHHELD
    assert {"armed", "position_ned", "global_position"} <= set(state.stale)
    assert state.attitude is not None  # the message that showed the reboot is taken in
    assert "attitude" not in state.stale
    assert not vehicle.streamer_active
    # no parameter had been read: none is read again, and the log says nothing of it (it
    # said "0 parameters read again after the reboot")
    await asyncio.sleep(0.05)
    assert not [e for e in told + drain(events) if e.kind == "params"]
