"""MAVLink FTP reads against a server that answers as PX4's mavlink_ftp does."""

from __future__ import annotations

import pytest

from server.link.plugins.ftp import (
    FtpClient,
    FtpError,
    decode_payload,
    encode_payload,
    kCmdReadFile,
)
from tests.link.conftest import ScriptedSession
from tests.link.ftp_server import FtpServer

FILE = bytes(range(256)) * 4 + b"end"  # several reads, the last one short


def _client(scripted: ScriptedSession, files: dict[str, bytes]) -> tuple[FtpClient, FtpServer]:
    server = FtpServer(scripted.peer, files)
    scripted.peer.on_message = server.handle
    client = scripted.vehicle.px4_events.ftp
    client.timeout_s = 0.05
    return client, server


def test_payload_layout_is_px4s() -> None:
    payload = encode_payload(7, 2, kCmdReadFile, 478, b"ab", size=239)
    assert len(payload) == 251
    assert bytes(payload[:12]) == bytes([7, 0, 2, kCmdReadFile, 239, 0, 0, 0, 222, 1, 0, 0])
    reply = decode_payload(payload)
    assert (reply.seq_number, reply.session, reply.offset) == (7, 2, 478)


async def test_download_reads_the_whole_file(scripted: ScriptedSession) -> None:
    client, server = _client(scripted, {"etc/extras/a.bin": FILE})
    assert await client.download("etc/extras/a.bin") == FILE
    assert server.reads == 5  # 239-byte reads
    assert not server.session_open  # TerminateSession


async def test_lost_replies_are_asked_again_and_never_executed_twice(
    scripted: ScriptedSession,
) -> None:
    client, server = _client(scripted, {"f": FILE})
    server.drop_every = 3
    assert await client.download("f") == FILE
    assert server.reads == 5  # re-sent requests were answered from PX4's last reply
    assert server.requests > 7


async def test_burst_read_streams_the_file(scripted: ScriptedSession) -> None:
    client, server = _client(scripted, {"f": FILE})
    server.burst_packets = 3  # a burst ends before the file does: the next one goes on
    assert await client.download("f") == FILE
    assert server.reads == 0
    assert server.bursts == 2


async def test_burst_read_fills_what_got_lost(scripted: ScriptedSession) -> None:
    client, server = _client(scripted, {"f": FILE})
    server.burst_packets = 10
    server.drop_every = 3
    assert await client.download("f") == FILE
    assert server.bursts > 1


async def test_nak_names_px4s_error(scripted: ScriptedSession) -> None:
    client, _ = _client(scripted, {})
    with pytest.raises(FtpError, match="FileNotFound"):
        await client.download("missing.json")


async def test_a_stale_session_is_reset(scripted: ScriptedSession) -> None:
    client, server = _client(scripted, {"f": b"data"})
    server.session_open = True  # left open by an earlier client
    assert await client.download("f") == b"data"


async def test_silence_is_an_error(scripted: ScriptedSession) -> None:
    client = scripted.vehicle.px4_events.ftp
    client.timeout_s, client.retries = 0.02, 2
    with pytest.raises(FtpError, match="no answer"):
        await client.download("f")
