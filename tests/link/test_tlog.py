from datetime import UTC, datetime
from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.tlog import TlogWriter, iter_tlog, tlog_path
from tests.waiting import wait_for


def _frame(src_system: int, seq: int, mav_type: int = mavlink.MAV_TYPE_QUADROTOR) -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=src_system, srcComponent=1)
    mav.seq = seq
    msg = mav.heartbeat_encode(mav_type, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0)
    return bytes(msg.pack(mav))


def test_tlog_path_is_utc_time_then_sanitised_link_name(tmp_path: Path) -> None:
    started = datetime(2026, 3, 4, 5, 6, 7, tzinfo=UTC)
    first = tlog_path(tmp_path, "udpin:127.0.0.1:24540", started)
    assert first.name == "20260304T050607Z-udpin_127.0.0.1_24540.tlog"
    first.touch()
    assert tlog_path(tmp_path, "udpin:127.0.0.1:24540", started).name == (
        "20260304T050607Z-udpin_127.0.0.1_24540-1.tlog"
    )


async def test_frames_reach_the_file_on_the_flush_timer_without_close(tmp_path: Path) -> None:
    writer = TlogWriter(tmp_path / "a.tlog", flush_interval_s=0.2)
    writer.start()
    try:
        writer.record(_frame(1, 0))
        assert writer.path.stat().st_size == 0  # buffered, not written per frame
        # polling the file is the point: nothing signals a write
        await wait_for(lambda: writer.path.stat().st_size > 0, 3.0, "the flush", poll_s=0.05)
        assert writer.path.stat().st_size == 8 + len(_frame(1, 0))
    finally:
        await writer.close()


async def test_buffer_is_bounded_by_writing_early(tmp_path: Path) -> None:
    frame = _frame(1, 0)
    writer = TlogWriter(tmp_path / "b.tlog", flush_interval_s=60.0,
                        max_buffer_bytes=3 * (8 + len(frame)))
    writer.start()
    try:
        for _ in range(3):
            writer.record(frame)
        assert writer.path.stat().st_size == 3 * (8 + len(frame))
    finally:
        await writer.close()


async def test_pymavlink_reads_back_both_directions_with_timestamps(tmp_path: Path) -> None:
    writer = TlogWriter(tmp_path / "c.tlog")
    writer.record(_frame(1, 7), unix_time_s=1_700_000_000.25)
    writer.record(_frame(255, 3, mavlink.MAV_TYPE_GCS), unix_time_s=1_700_000_000.5)
    await writer.close()

    conn = mavutil.mavlink_connection(str(writer.path), dialect="development")
    got = []
    while (msg := conn.recv_match(blocking=False)) is not None:
        got.append((msg.get_srcSystem(), msg.get_seq(), msg.type, msg._timestamp))
    conn.close()
    assert got == [
        (1, 7, mavlink.MAV_TYPE_QUADROTOR, 1_700_000_000.25),
        (255, 3, mavlink.MAV_TYPE_GCS, 1_700_000_000.5),
    ]


async def test_iter_tlog_stops_at_a_truncated_last_record(tmp_path: Path) -> None:
    frame_v2 = _frame(1, 1)
    mav1 = mavlink.MAVLink(None, srcSystem=2, srcComponent=1)
    frame_v1 = bytes(mav1.heartbeat_encode(2, 12, 0, 0, 0).pack(mav1, force_mavlink1=True))
    writer = TlogWriter(tmp_path / "d.tlog")
    writer.record(frame_v2, unix_time_s=10.0)
    writer.record(frame_v1, unix_time_s=11.0)
    writer.record(frame_v2[:5], unix_time_s=12.0)
    await writer.close()

    assert list(iter_tlog(writer.path)) == [(10.0, frame_v2), (11.0, frame_v1)]
