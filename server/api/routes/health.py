"""Liveness without a token: what the Docker HEALTHCHECK and `skyhelm serve` probe."""

from __future__ import annotations

import functools
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from fastapi import APIRouter, Request

from server.http.deps import Context
from server.http.routing import route
from server.http.schemas import ChildProcessOut, HealthOut
from server.link.stream.stream_channel import sender_status
from skyhelm_wire.calls import API_PREFIX, CALL

router = APIRouter(prefix=API_PREFIX, tags=["health"])


@functools.cache
def _version() -> str:
    try:
        return version("skyhelm")
    except PackageNotFoundError:
        return "0+unknown"


@route(router, CALL["health"])
async def health(context: Context, request: Request) -> HealthOut:
    processes: list[dict[str, Any]] = []
    sender = sender_status()
    if sender is not None:
        processes.append(sender)
    for child in (getattr(request.app.state, "foxglove", None),
                  getattr(request.app.state, "sim", None)):
        if child is not None:
            processes.append(child.status())
    return HealthOut(
        status="ok",
        version=_version(),
        vehicles=len(context.registry.all()),
        read_only=context.read_only,
        processes=[ChildProcessOut(**p) for p in processes],
    )
