"""Every route of the OpenAPI and every WebSocket endpoint, tried without a token, with the
observer token, and with the pilot token but without the lease (another session holds it):
each unauthorised control path answers 401/403/409/423 (429 is security.py's, see
test_security_limits.py), and docs/api.md lists each one with these answers. The control
socket's message rate limit (429 answers, then a 1008 close) is here too."""

from __future__ import annotations

import json
import re
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi import FastAPI
from fastapi.routing import APIRoute, APIWebSocketRoute, iter_route_contexts
from websockets.asyncio.client import connect

from server.control.auth import Role
from tests.api.conftest import OBSERVER, PILOT, Api, api_for, auth, sim_cluster
from tests.api.test_ws import Served, close_code, receive, receive_until, served
from tests.serving import uvicorn_serving

API_MD = Path(__file__).resolve().parents[2] / "docs" / "api.md"
PATH_VALUES = {
    "vehicle_id": "1", "name": "MPC_XY_VEL_MAX", "request_id": "no-such-request",
    "edge": "edge-a", "rest": "arm", "z": "1", "x": "0", "y": "0", "ext": "png",
}
# What each caller gets where the rule by method does not hold: health is public; a session
# cookie may be had by any token; POST /control is how a pilot asks for the lease (409 while
# another holds it).
READ = 0  # admitted: whatever the read answers (200, or 503 when the vehicle is not talking)
REFUSALS = frozenset({401, 403, 409, 423, 429})
EXCEPTIONS: dict[tuple[str, str], tuple[int, int, int]] = {
    ("GET", "/api/v1/health"): (READ, READ, READ),
    ("POST", "/api/v1/session"): (401, READ, READ),
    ("DELETE", "/api/v1/session"): (401, READ, READ),
    ("POST", "/api/v1/vehicles/{vehicle_id}/control"): (401, 403, 409),
    # server-wide, not per vehicle: the pilot token without any lease; 409 here (no
    # signing_key_file), and always while a vehicle is armed (PX4 refuses SETUP_SIGNING)
    ("POST", "/api/v1/signing"): (401, 403, 409),
}
# A body that passes validation where {} would not, so the answer is the lease's, not a 422.
_V = "/api/v1/vehicles/{vehicle_id}"
# a body each route takes (the input is checked before the lease: {} would be a 422 there)
BODIES: dict[tuple[str, str], dict[str, Any]] = {
    ("POST", f"{_V}/control/requests/{{request_id}}"): {"grant": True},
    ("POST", "/api/v1/signing"): {"action": "generate"},
    ("POST", f"{_V}/mode"): {"mode": "HOLD"},
    ("POST", f"{_V}/reposition"): {"lat_deg": 0.0, "lon_deg": 0.0},
    ("POST", f"{_V}/vtol/transition"): {"to": "multicopter"},
    ("POST", f"{_V}/origin"): {"lat_deg": 0.0, "lon_deg": 0.0, "alt_amsl_m": 0.0},
    ("POST", f"{_V}/intents/goto"): {"lat_deg": 0.0, "lon_deg": 0.0},
    ("PUT", f"{_V}/setpoint"): {"type": "position_ned", "north_m": 0.0, "east_m": 0.0,
                                "down_m": 0.0},
    ("PUT", f"{_V}/params/{{name}}"): {"value": 1.0},
}
SOCKETS: dict[str, tuple[int, int | None, int]] = {
    # no token, observer (None: admitted), pilot without the lease
    "/api/v1/ws/telemetry": (4401, None, 0),
    "/api/v1/ws/control": (4401, 4403, 4409),
}
# a fleet server's (--fleet) own socket; its routes follow the rule by method
# (tests/fleet/test_fleet_processes.py tries them against real edges)
FLEET_SOCKETS: dict[str, tuple[int, int | None, int]] = {"/api/v1/fleet/ws": (4401, None, 0)}


def expected(method: str, path: str) -> tuple[int, int, int]:
    """(no token, observer, pilot without the lease)."""
    if (method, path) in EXCEPTIONS:
        return EXCEPTIONS[(method, path)]
    if method == "GET":
        return 401, READ, READ
    return 401, 403, 423


def routes(app: FastAPI) -> tuple[list[tuple[str, str]], list[str]]:
    rest, sockets = [], []
    for context in iter_route_contexts(app.router.routes):
        route = context.original_route
        if isinstance(route, APIRoute) and route.include_in_schema:
            rest += [(method, context.path) for method in sorted(context.methods or ())]
        elif isinstance(route, APIWebSocketRoute):
            sockets.append(context.path)
    return rest, sockets


def concrete(path: str) -> str:
    return re.sub(r"\{(\w+)\}", lambda match: PATH_VALUES[match.group(1)], path)


@pytest.fixture
async def held() -> AsyncIterator[Api]:
    """A live quad whose lease another pilot session holds."""
    async with sim_cluster("quad") as sim, api_for(sim) as api:
        await api.wait_ready()
        await api.take_control()
        yield api


async def test_every_route_refuses_who_may_not_call_it(held: Api) -> None:
    rest, sockets = routes(held.app)
    openapi_paths = held.app.openapi()["paths"]
    assert len(rest) == sum(len(ops) for ops in openapi_paths.values())
    assert len(rest) >= 30
    assert set(sockets) == set(SOCKETS)
    callers: dict[str, dict[str, str]] = {
        "no token": {},
        "observer": auth(OBSERVER),
        "pilot, no lease": auth(PILOT),
    }
    wrong: list[str] = []
    async with httpx.AsyncClient(
        transport=httpx.ASGITransport(app=held.app), base_url="http://testserver"
    ) as client:
        for method, path in rest:
            got = []
            for headers in callers.values():
                client.cookies.clear()  # POST /session sets one: each caller brings its own
                body = None if method in ("GET", "DELETE") else BODIES.get((method, path), {})
                response = await client.request(method, concrete(path), json=body, headers=headers)
                code = response.status_code
                got.append(code if code in REFUSALS or code == 500 else READ)
            if tuple(got) != expected(method, path):
                wrong.append(f"{method} {path}: {got} != {expected(method, path)}")
    assert not wrong, "\n".join(wrong)
    # the lease is untouched: nobody but its holder moved it
    assert held.app.state.api.leases.current(1).lease_id == held.lease_headers["X-Lease-Id"]

    async with uvicorn_serving(held.app) as host:
        for path, codes in SOCKETS.items():
            url = f"ws://{host}{path}?vehicle=1"
            for token, want in zip((None, OBSERVER, PILOT), codes, strict=True):
                with_token = f"{url}&token={token}" if token else url
                async with connect(with_token) as ws:
                    if want in (None, 0):
                        assert (await receive(ws))["type"] in ("vehicles", "state"), path
                    else:
                        assert await close_code(ws) == want, (path, token)


def test_docs_list_every_route_with_its_refusals() -> None:
    """docs/api.md has one table row per route: `METHOD path` and the three answers."""
    from server.app import create_app
    from tests.api.conftest import make_settings

    # a fleet server has every route of a server, and the fleet's
    app = create_app(make_settings(None, connect=["udpin:127.0.0.1:0"], fleet=True))
    rest, sockets = routes(app)
    assert set(sockets) == set(SOCKETS) | set(FLEET_SOCKETS)
    text = API_MD.read_text()
    missing = []
    for method, path in rest:
        answers = ["read" if code == READ else str(code) for code in expected(method, path)]
        row = f"| `{method} {path}` | {' | '.join(answers)} |"
        if row not in text:
            missing.append(row)
    for path, (no_token, observer, pilot) in {**SOCKETS, **FLEET_SOCKETS}.items():
        row = (
            f"| `WS {path}` | close {no_token} | "
            f"{'admitted' if observer is None else f'close {observer}'} | "
            f"{'admitted' if pilot == 0 else f'close {pilot}'} |"
        )
        if row not in text:
            missing.append(row)
    assert not missing, "docs/api.md lacks:\n" + "\n".join(missing)


# --- the control socket's rate limit -------------------------------------------------------


@pytest.fixture
async def strict_socket() -> AsyncIterator[Served]:
    limits: dict[str, Any] = {
        "ws_message_rate_per_s": 0.01,  # no refill within the test, however slow the machine
        "ws_message_burst": 4,
        "ws_abuse_close_after": 6,
    }
    async with served(**limits) as s:
        yield s


async def test_control_socket_answers_429_then_closes_on_sustained_abuse(
    strict_socket: Served,
) -> None:
    served_ = strict_socket
    async with connect(served_.url("control", vehicle=1, client_name="flood")) as ws:
        assert (await receive(ws))["type"] == "lease"
        for request_id in range(1, 5):  # the burst
            await ws.send(json.dumps({"type": "heartbeat", "id": request_id}))
            assert (await receive_until(ws, {"id": request_id}))["status"] == 200
        await ws.send(json.dumps({"type": "heartbeat", "id": 5}))
        refused = await receive_until(ws, {"id": 5})
        assert (refused["status"], refused["ok"], refused["request"]) == (429, False, "heartbeat")
        assert 0 < refused["body"]["detail"]["retry_after_s"] <= 100.0
        assert "rate limit" in refused["body"]["detail"]["reason"]
        await ws.send("not json at all")  # refused before it is even parsed
        assert (await receive_until(ws, {"type": "result"}))["status"] == 429
        for request_id in range(7, 11):
            await ws.send(json.dumps({"type": "setpoint", "id": request_id}))
        last = await receive_until(ws, {"type": "error"})
        assert "closing" in last["reason"]
        assert last["retry_after_s"] > 0
        assert await close_code(ws) == 1008
    # the lease went with the socket; the pilot's token may come back (a new bucket is not
    # given: the same token's bucket refills at its rate)
    control = served_.api.app.state.api.leases.current(1)
    assert control is None
    assert served_.api.app.state.api.guards.ws_messages.take(Role.PILOT.value) > 0
