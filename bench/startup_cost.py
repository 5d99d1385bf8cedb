"""What a server costs before it does anything: CPU seconds of `skyhelm serve` (embedded
simulated quad) to its ready line, and of an app's first calls (the routes it resolves),
with the API's routes shared by every app as create_app mounts them, against the same routes
included with FastAPI's include_router, which builds each route again for each app.

Run: .venv/bin/python -m bench.startup_cost [--quick]
Writes bench/results/startup_cost.json.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import httpx
from fastapi import APIRouter, FastAPI
from fastapi.routing import APIRoute, APIWebSocketRoute

from bench._results import machine_info, write_results
from bench._serve import cpu_seconds, served
from server.app import create_app
from server.settings import load_settings

TOKEN = "startup-cost-token"
# paths of early, middle and late routers, as a script's first calls reach them
FIRST_CALLS = ("/api/v1/health", "/api/v1/vehicles", "/api/v1/vehicles/7",
               "/api/v1/vehicles/7/params")


async def serve_to_ready() -> dict[str, float]:
    """One `skyhelm serve --port 0`: seconds and the server's CPU seconds to its ready line."""
    command = [str(Path(sys.executable).with_name("skyhelm")), "serve", "--port", "0",
               f"--token={TOKEN}", "--no-tlog", "--no-scene"]  # fmt: skip
    started = time.perf_counter()
    async with served(command) as (process, _):
        return {"ready_s": time.perf_counter() - started,
                "server_cpu_s": cpu_seconds(process.pid)}  # fmt: skip


def _settings() -> Any:
    return load_settings(connect=["udpin:127.0.0.1:0"], token=TOKEN, scene=False,
                         log_dir=None, web_dir=None)  # fmt: skip


def shared_routes_app() -> FastAPI:
    return create_app(_settings())


def included_routes_app() -> FastAPI:
    """The same app with its API routes included with FastAPI's include_router instead."""
    app = create_app(_settings())
    api = [r for r in app.router.routes if isinstance(r, APIRoute | APIWebSocketRoute)]
    app.router.routes[:] = [r for r in app.router.routes if r not in api]
    routes = APIRouter()
    routes.routes.extend(api)
    app.include_router(routes)
    return app


async def _first_calls(app: FastAPI) -> None:
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://bench",
                                 headers={"Authorization": f"Bearer {TOKEN}"}) as client:
        for path in FIRST_CALLS:
            await client.get(path)


def app_and_first_calls(make: Any) -> float:
    """CPU seconds of making an app and its first calls."""
    started = time.process_time()
    asyncio.run(_first_calls(make()))
    return time.process_time() - started


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 serve starts, 5 apps each")
    options = parser.parse_args()
    starts, apps = (3, 5) if options.quick else (7, 15)
    load_before = os.getloadavg()
    app_and_first_calls(shared_routes_app)  # imports and module-level routes, once
    shared = [app_and_first_calls(shared_routes_app) for _ in range(apps)]
    included = [app_and_first_calls(included_routes_app) for _ in range(apps)]
    serves = [asyncio.run(serve_to_ready()) for _ in range(starts)]
    cost = {
        "shared_routes": round(statistics.median(shared), 4),
        "include_router": round(statistics.median(included), 4),
    }
    result: dict[str, Any] = {
        "apps": apps,
        "app_first_calls_cpu_s": cost,
        "serve_starts": starts,
        "serve_ready_s": round(statistics.median(s["ready_s"] for s in serves), 2),
        "serve_cpu_s": round(statistics.median(s["server_cpu_s"] for s in serves), 2),
        "machine": machine_info(load_before),
    }
    print(f"an app and its first calls ({len(FIRST_CALLS)} paths), median of {apps}: "
          f"{cost['shared_routes']:.3f} CPU-s with the shared routes, "
          f"{cost['include_router']:.3f} CPU-s with include_router")
    print(f"skyhelm serve (embedded quad, no scene) to its ready line, median of {starts}: "
          f"{result['serve_ready_s']:.2f} s, {result['serve_cpu_s']:.2f} CPU-s of the server")
    write_results("startup_cost", result)
    return 0 if cost["shared_routes"] < cost["include_router"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
