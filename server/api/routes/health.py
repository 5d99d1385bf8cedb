"""Liveness without a token: what the Docker HEALTHCHECK and `skyhelm serve` probe."""

from __future__ import annotations

import functools
from importlib.metadata import PackageNotFoundError, version

from fastapi import APIRouter

from server.http.deps import Context
from server.http.schemas import HealthOut

router = APIRouter(tags=["health"])


@functools.cache
def _version() -> str:
    try:
        return version("skyhelm")
    except PackageNotFoundError:
        return "0+unknown"


@router.get("/health", response_model=HealthOut)
async def health(context: Context) -> HealthOut:
    return HealthOut(
        status="ok",
        version=_version(),
        vehicles=len(context.registry.all()),
        read_only=context.read_only,
    )
