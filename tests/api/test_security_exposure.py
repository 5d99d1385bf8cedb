"""Exposure: security headers and CSP per area, Origin checks on WebSockets (refused at the
handshake) and on state-changing REST calls, the page's session cookie, the lockout at a
WebSocket handshake, and that no log line (uvicorn's access and error logs included)
carries a token. No vehicle: the app runs with an empty registry on a real uvicorn."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import uvicorn
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from server.http.security import DOCS_CSP, PAGE_CSP, SCENE_CSP, csp_for
from tests.api.conftest import OBSERVER, PILOT, Api, api_for, auth
from tests.api.test_ws import close_code, receive
from tests.serving import uvicorn_serving
from tests.waiting import eventually

WEB_DIR = Path(__file__).resolve().parents[2] / "web"
NO_VEHICLE = ["udpin:127.0.0.1:0"]


@contextlib.asynccontextmanager
async def empty(**overrides: Any) -> AsyncIterator[Api]:
    async with api_for(None, connect=NO_VEHICLE, web_dir=WEB_DIR, **overrides) as api:
        yield api


async def test_every_answer_carries_the_security_headers() -> None:
    async with empty() as api:
        client = api.client
        answers = {
            "/index.html": await client.get("/index.html"),
            "/api/v1/vehicles": await client.get("/api/v1/vehicles"),
            "/api/v1/vehicles?bad": await client.get("/api/v1/vehicles", headers=auth("nope-nope")),
            "/docs": await client.get("/docs"),
            "/openapi.json": await client.get("/openapi.json"),
        }
        for path, response in answers.items():
            assert response.headers["x-content-type-options"] == "nosniff", path
            assert response.headers["referrer-policy"] == "no-referrer", path
            assert "frame-ancestors 'self'" in response.headers["content-security-policy"], path
        assert answers["/index.html"].status_code == 200
        assert answers["/index.html"].headers["content-security-policy"] == PAGE_CSP
        assert answers["/api/v1/vehicles?bad"].status_code == 401
        assert answers["/docs"].headers["content-security-policy"] == DOCS_CSP
    assert csp_for("/scene/") == SCENE_CSP
    assert csp_for("/scene/assets/x.js") == SCENE_CSP
    assert csp_for("/sceneless") == PAGE_CSP
    assert "script-src 'self';" in PAGE_CSP  # the page runs no inline script


async def test_state_changing_calls_from_a_foreign_origin_are_refused() -> None:
    async with empty(cors_origins=["https://ops.example"]) as api:
        client = api.client
        foreign = {"Origin": "https://evil.example"}
        refused = await client.post("/api/v1/vehicles/1/control", json={}, headers=foreign)
        assert refused.status_code == 403
        assert refused.json()["detail"] == {"reason": "origin not allowed", "field": "Origin"}
        # reads are left to CORS (the browser withholds the answer), scripts send no Origin
        assert (await client.get("/api/v1/vehicles", headers=foreign)).status_code == 200
        for allowed in ("https://ops.example", "http://testserver"):
            response = await client.post(
                "/api/v1/vehicles/1/control", json={}, headers={"Origin": allowed}
            )
            assert response.status_code == 404, allowed  # past the check: no vehicle 1
        assert (await client.post("/api/v1/vehicles/1/control", json={})).status_code == 404


async def test_browser_sockets_from_a_foreign_origin_are_refused_at_the_handshake() -> None:
    async with empty(cors_origins=["https://ops.example"]) as api, uvicorn_serving(api.app) as host:
        url = f"ws://{host}/api/v1/ws/telemetry?token={PILOT}"
        for path in ("telemetry", "control?vehicle=1"):
            with pytest.raises(InvalidStatus) as refused:
                async with connect(
                    f"ws://{host}/api/v1/ws/{path}{'&' if '?' in path else '?'}token={PILOT}",
                    origin="http://evil.example",  # type: ignore[arg-type]
                ):
                    pass
            assert refused.value.response.status_code == 403
            assert b"origin not allowed" in refused.value.response.body
        for origin in ("https://ops.example", f"http://{host}", None):
            async with connect(url, origin=origin) as ws:  # type: ignore[arg-type]
                assert (await receive(ws, 10.0))["type"] == "vehicles", origin
        # no Origin (a script) still needs its token
        async with connect(f"ws://{host}/api/v1/ws/telemetry") as ws:
            assert await close_code(ws) == 4401


async def test_the_session_cookie_carries_the_token_for_sockets_only_when_set() -> None:
    async with empty() as api, uvicorn_serving(api.app) as host:
        async with httpx.AsyncClient(base_url=f"http://{host}") as client:
            opened = await client.post("/api/v1/session", headers=auth(OBSERVER))
            assert opened.status_code == 200
            assert opened.json() == {"role": "observer"}
            cookie = opened.headers["set-cookie"]
            assert cookie.startswith(f"skyhelm_token={OBSERVER};")
            for attribute in ("HttpOnly", "Path=/", "SameSite=strict"):
                assert attribute in cookie
            assert "Secure" not in cookie  # plain http here; https below
            refused = await client.post("/api/v1/session", headers=auth("not-the-token"))
            assert refused.status_code == 401
            assert "set-cookie" not in refused.headers
            closed = await client.delete("/api/v1/session", headers=auth(OBSERVER))
            assert closed.status_code == 204
            assert 'skyhelm_token=""' in closed.headers["set-cookie"]
        cookie_header = {"Cookie": f"skyhelm_token={OBSERVER}"}
        async with connect(
            f"ws://{host}/api/v1/ws/telemetry",
            additional_headers=cookie_header,
            origin=f"http://{host}",  # type: ignore[arg-type]
        ) as ws:
            assert (await receive(ws, 10.0))["type"] == "vehicles"
    async with (
        empty() as api,
        httpx.AsyncClient(
            transport=httpx.ASGITransport(app=api.app), base_url="https://testserver"
        ) as tls_client,
    ):
        opened = await tls_client.post("/api/v1/session", headers=auth(PILOT))
        assert "Secure" in opened.headers["set-cookie"]


async def test_a_locked_out_address_gets_429_at_the_socket_handshake() -> None:
    async with (
        empty(lockout_free_failures=2, lockout_base_s=30.0) as api,
        uvicorn_serving(api.app) as host,
    ):
        for _ in range(3):
            async with connect(f"ws://{host}/api/v1/ws/telemetry?token=guess-guess") as ws:
                assert await close_code(ws) == 4401
        with pytest.raises(InvalidStatus) as locked:
            async with connect(f"ws://{host}/api/v1/ws/telemetry?token={PILOT}"):
                pass
        assert locked.value.response.status_code == 429
        assert 25 <= int(locked.value.response.headers["Retry-After"]) <= 30
        assert b"wrong tokens" in locked.value.response.body


async def test_no_log_line_carries_a_token(caplog: pytest.LogCaptureFixture) -> None:
    wrong = "wrong-token-in-the-log"
    async with empty() as api:
        config = uvicorn.Config(
            api.app, host="127.0.0.1", port=0, log_config=None, access_log=True,
            lifespan="off", ws="websockets-sansio",
        )
        server = uvicorn.Server(config)
        task = asyncio.create_task(server.serve())
        try:
            await eventually(lambda: _started(server), 10.0, "uvicorn to listen")
            host = f"127.0.0.1:{server.servers[0].sockets[0].getsockname()[1]}"
            with caplog.at_level(logging.INFO):
                async with httpx.AsyncClient(base_url=f"http://{host}") as client:
                    await client.get("/api/v1/vehicles", params={"token": PILOT, "x": "1"})
                    await client.get("/api/v1/vehicles", headers=auth(PILOT))
                    await client.get("/api/v1/vehicles", params={"token": wrong})
                    await client.post("/api/v1/session", headers=auth(PILOT))
                    await client.get("/?token=" + PILOT)
                async with connect(f"ws://{host}/api/v1/ws/telemetry?token={PILOT}") as ws:
                    await receive(ws, 10.0)
                async with connect(f"ws://{host}/api/v1/ws/telemetry?token={wrong}") as ws:
                    await close_code(ws)
                logging.getLogger("server.api").warning(
                    "client sent Authorization: Bearer %s and cookie skyhelm_token=%s",
                    PILOT, PILOT,
                )
        finally:
            server.should_exit = True
            await asyncio.wait_for(task, 10.0)
    lines = [record.getMessage() for record in caplog.records]
    requests = [line for line in lines if "/api/v1/vehicles" in line]
    assert len(requests) >= 3, lines  # the access log is on and was captured
    assert any("token=***&x=1" in line for line in requests), requests
    assert any('"WebSocket /api/v1/ws/telemetry?token=***"' in line for line in lines), lines
    assert "client sent Authorization: Bearer *** and cookie skyhelm_token=***" in lines
    leaked = [line for line in lines if PILOT in line or wrong in line]
    assert not leaked, leaked


async def _started(server: uvicorn.Server) -> bool:
    return server.started
