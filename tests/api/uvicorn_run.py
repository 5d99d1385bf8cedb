"""`skyhelm serve`'s own uvicorn server, run in the test's event loop."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator

from server.cli import uvicorn_server
from server.settings import Settings
from tests.waiting import eventually


@contextlib.asynccontextmanager
async def uvicorn_serving(settings: Settings) -> AsyncIterator[int]:
    """The port it listens on, once it does; stopped on the way out."""
    server = uvicorn_server(settings)
    task = asyncio.create_task(server.serve())

    async def started() -> bool:
        if task.done():
            task.result()
        return server.started

    try:
        await eventually(started, 20.0, "uvicorn to listen")
        port: int = server.servers[0].sockets[0].getsockname()[1]
        yield port
    finally:
        server.should_exit = True
        await asyncio.wait_for(task, 20.0)
