"""A frame tap sees what the .tlog records, both directions (a send from another thread
too, as the setpoint sender thread sends), from the first frame to the last."""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from server.link import Link
from server.link.codec.tlog import iter_tlog

from .test_link import _heartbeat, _peer, _statustext, _until


async def test_a_tap_added_on_open_sees_every_frame_the_tlog_records(tmp_path: Path) -> None:
    seen: list[tuple[bytes, bool, float]] = []

    def tap(msg: mavlink.MAVLink_message, sent: bool, unix_time_s: float) -> None:
        seen.append((bytes(msg.get_msgbuf()), sent, unix_time_s))

    async with _peer() as peer:
        link = await Link.open(f"udpout:127.0.0.1:{peer.port}", log_dir=tmp_path,
                               on_open=lambda opened: opened.add_frame_tap(tap))
        try:
            await _until(lambda: peer.heartbeats_from(255))  # the link introduced itself
            for seq in range(3):
                peer.send(_heartbeat(), link, seq=seq)
            peer.send(_statustext("hello"), link, seq=3)
            command = link.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
            sender = threading.Thread(target=link.send, args=(command,))
            sender.start()
            sender.join()
            await _until(lambda: sum(not sent for _, sent, _ in seen) == 4
                         and any(sent and f[7:10] == b"\x4c\x00\x00" for f, sent, _ in seen))
        finally:
            await link.close()
            tlog_path = link.tlog_path
        frames_after_close = len(seen)
        link.send_gcs_heartbeat()  # closed: neither records it
        await asyncio.sleep(0)
    assert tlog_path is not None
    recorded: list[Any] = [(frame, unix_time_s) for unix_time_s, frame in iter_tlog(tlog_path)]
    # the .tlog keeps whole microseconds
    assert [(frame, int(t * 1e6)) for frame, _, t in seen] == [
        (frame, round(t * 1e6)) for frame, t in recorded]
    assert len(seen) == frames_after_close
    assert {sent for _, sent, _ in seen} == {True, False}
