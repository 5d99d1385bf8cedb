"""An idle keep-alive connection outlives a pooling client's own limit: httpx drops idle
connections after 5 s, so the server must not close them at 5 s too (uvicorn's default),
or a request sent just then meets "connection reset by peer" without reaching the server."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import pytest

from server.cli import KEEP_ALIVE_S
from server.settings import load_settings
from tests.api.conftest import PILOT
from tests.api.uvicorn_run import uvicorn_serving

# idle longer than httpx's keep-alive expiry and uvicorn's default timeout (both 5 s)
IDLE_S = 6.0


@pytest.fixture
async def http_port() -> AsyncIterator[int]:
    settings = load_settings(port=0, token=PILOT, connect=["udpin:127.0.0.1:0"], scene=False,
                             log_dir=None, access_log=False)
    async with uvicorn_serving(settings) as port:
        yield port


async def _get(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> bytes:
    writer.write(b"GET /api/v1/health HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    await writer.drain()
    head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), 10.0)
    length = next(int(line.split(b":")[1]) for line in head.split(b"\r\n")
                  if line.lower().startswith(b"content-length:"))
    await asyncio.wait_for(reader.readexactly(length), 10.0)
    return head.split(b"\r\n")[0]


async def test_an_idle_connection_still_answers_after_a_pooling_clients_limit(
    http_port: int,
) -> None:
    assert KEEP_ALIVE_S > IDLE_S
    reader, writer = await asyncio.open_connection("127.0.0.1", http_port)
    try:
        assert await _get(reader, writer) == b"HTTP/1.1 200 OK"
        await asyncio.sleep(IDLE_S)
        # the same connection, as a pool reuses it
        assert await _get(reader, writer) == b"HTTP/1.1 200 OK"
    finally:
        writer.close()
