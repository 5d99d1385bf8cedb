"""The edge's api queryable against a small app of its own (no vehicle): what of a query
reaches the app, what of the app's answer goes back, and the answers the edge gives itself
(bad path or payload, a call too slow, too many at once), over real Zenoh on loopback; and
how the edge numbers a vehicle's state samples."""

from __future__ import annotations

import asyncio
import json
import logging
import socket
from collections.abc import AsyncIterator
from typing import Any

import pytest
import pytest_asyncio
import zenoh
from fastapi import FastAPI, Request, Response

from server.app import StartupError
from server.control.publisher import Published
from server.fleet.edge_api import EdgeApi, check_path
from server.fleet.edge_publish import Sequence
from server.fleet.proxy import call_timeout_s
from server.fleet.session import open_session
from tests.api.conftest import app_running, make_settings
from tests.fleet.fake_edge import free_tcp_endpoint, loopback_options
from tests.waiting import eventually

pytestmark = pytest.mark.asyncio(loop_scope="module")

KEY = "skyhelm/apitest/edge-u/api"


def echo_app() -> FastAPI:
    app = FastAPI()

    @app.post("/api/v1/echo")
    async def echo(request: Request) -> dict[str, Any]:
        client = request.client
        return {
            "client": [client.host, client.port] if client else None,
            "headers": sorted(request.headers.keys()),
            "authorization": request.headers.get("authorization"),
            "query": str(request.query_params),
            "body": await request.json(),
        }

    @app.get("/api/v1/busy")
    async def busy() -> Response:
        return Response(
            b"slow down", status_code=429, media_type="text/plain",
            headers={"Retry-After": "3", "X-Internal": "no"},
        )

    @app.get("/api/v1/slow")
    async def slow() -> dict[str, bool]:
        await asyncio.sleep(30.0)
        return {"late": True}

    @app.get("/api/v1/boom")
    async def boom() -> None:
        raise RuntimeError("the app failed")

    @app.delete("/api/v1/empty", status_code=204)
    async def empty() -> Response:
        return Response(status_code=204)

    return app


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def edge_api() -> AsyncIterator[EdgeApi]:
    api = EdgeApi(echo_app(), KEY, call_timeout_s=0.5)
    yield api
    await api.close()


async def test_the_app_sees_the_callers_authority_only_from_address_zenoh(
    edge_api: EdgeApi,
) -> None:
    call = {
        "method": "post", "path": "/api/v1/echo", "query": "a=1&b=two",
        "headers": {"Authorization": "Bearer abc", "X-Lease-Id": "L1", "Cookie": "t=x",
                    "Origin": "http://evil.example", "X-Forwarded-For": "10.0.0.1"},
        "body": {"altitude_m": 5.0, "list": [1, None]},
    }
    reply = await edge_api.run(json.dumps(call).encode())
    assert reply["status"] == 200, reply
    body = reply["body"]
    assert body["client"] == ["zenoh", 0]
    assert body["authorization"] == "Bearer abc"
    assert "cookie" not in body["headers"]
    assert "origin" not in body["headers"]
    assert "x-forwarded-for" not in body["headers"]
    assert "x-lease-id" in body["headers"]
    assert body["query"] == "a=1&b=two"
    assert body["body"] == {"altitude_m": 5.0, "list": [1, None]}
    assert reply["headers"] == {"content-type": "application/json"}


async def test_the_apps_answer_goes_back_with_its_status_and_selected_headers(
    edge_api: EdgeApi,
) -> None:
    busy = await edge_api.run(b'{"method": "GET", "path": "/api/v1/busy"}')
    assert busy["status"] == 429
    assert busy["body"] == "slow down"  # not JSON: the text
    assert busy["headers"]["retry-after"] == "3"
    assert "x-internal" not in busy["headers"]
    empty = await edge_api.run(b'{"method": "DELETE", "path": "/api/v1/empty"}')
    assert empty["status"] == 204
    assert empty["body"] is None
    missing = await edge_api.run(b'{"method": "GET", "path": "/api/v1/nothing-here"}')
    assert missing["status"] == 404
    failed = await edge_api.run(b'{"method": "GET", "path": "/api/v1/boom"}')
    assert failed["status"] == 500  # the app's own answer to its error; the edge goes on
    assert (await edge_api.run(b'{"method": "DELETE", "path": "/api/v1/empty"}'))["status"] == 204


async def test_a_call_that_does_not_finish_is_504(edge_api: EdgeApi) -> None:
    reply = await edge_api.run(b'{"method": "GET", "path": "/api/v1/slow"}')
    assert reply["status"] == 504
    assert "did not finish" in reply["body"]["detail"]["reason"]


@pytest.mark.parametrize(
    ("payload", "status", "field"),
    [
        (b"", 422, "payload"),
        (b"[1, 2]", 422, "payload"),
        (b"\xff\xfe", 422, "payload"),
        (b'{"method": "GET"}', 422, "path"),
        (b'{"method": 7, "path": "/api/v1/echo"}', 422, "method"),
        (b'{"method": "GET", "path": "/api/v1/echo", "query": 5}', 422, "query"),
        (b'{"method": "GET", "path": "/api/v1/echo", "headers": {"a": 1}}', 422, "headers"),
        (b'{"method": "GET", "path": "/api/v1/../../etc/passwd"}', 404, "path"),
        (b'{"method": "GET", "path": "/api/v1/fleet/edges/x/vehicles/1"}', 404, "path"),
        (b'{"method": "GET", "path": "/api/v1/echo\\r\\nX: y"}', 404, "path"),
        (b'{"method": "POST", "path": "/api/v1/echo", "body": NaN}', 422, "body"),
        (b"{" + b" " * (1 << 20) + b"}", 413, "payload"),
    ],
)
async def test_what_is_not_a_call_is_answered_with_why(
    edge_api: EdgeApi, payload: bytes, status: int, field: str
) -> None:
    reply = await edge_api.run(payload)
    assert reply["status"] == status, reply
    assert reply["body"]["detail"]["field"] == field


async def test_an_ask_for_control_has_the_holders_time_on_top_of_the_call_timeout() -> None:
    ask = {"takeover": True, "client_name": "me"}
    assert call_timeout_s("POST", "control", ask, takeover_ask_s=10.0) == 15.0
    assert call_timeout_s("POST", "control", ask, takeover_ask_s=3.0, base_s=1.0) == 4.0
    # answered at once: a forced takeover, a plain acquire, anything else
    assert call_timeout_s("POST", "control", {**ask, "force": True}, 10.0) == 5.0
    assert call_timeout_s("POST", "control", {}, 10.0) == 5.0
    assert call_timeout_s("POST", "control", None, 10.0) == 5.0
    assert call_timeout_s("PUT", "control", ask, 10.0) == 5.0
    assert call_timeout_s("POST", "arm", ask, 10.0) == 5.0


async def test_paths_under_the_api_only() -> None:
    check_path("/api/v1/vehicles/1/params/MPC_XY_VEL_MAX")
    check_path("/api/v1/vehicles/1/arm")


async def test_every_query_is_answered_even_when_busy_or_stopping() -> None:
    endpoint = free_tcp_endpoint()
    edge_session = await asyncio.to_thread(open_session, loopback_options(listen=[endpoint]))
    caller = await asyncio.to_thread(open_session, loopback_options(connect=[endpoint]))
    api = EdgeApi(echo_app(), KEY, max_in_flight=0)
    api.bind()
    queryable = edge_session.declare_queryable(
        KEY, zenoh.handlers.Callback(api.on_query), complete=True
    )

    def ask() -> list[dict[str, Any]]:
        replies = caller.get(KEY, payload=b'{"method": "GET", "path": "/api/v1/busy"}',
                             timeout=10.0)
        return [json.loads(r.ok.payload.to_bytes()) for r in replies if r.ok is not None]

    try:
        # the queryable's declaration reaches the caller shortly after it connects
        busy = await eventually(lambda: asyncio.to_thread(ask), 10.0, "a reply")
        assert [r["status"] for r in busy] == [503]
        assert "running 0 calls" in busy[0]["body"]["detail"]["reason"]
        await api.close()
        stopping = await asyncio.to_thread(ask)
        assert [r["status"] for r in stopping] == [503]
        assert stopping[0]["body"]["detail"]["reason"] == "the edge is stopping"
    finally:
        queryable.undeclare()  # type: ignore[no-untyped-call]
        await asyncio.to_thread(caller.close)
        await asyncio.to_thread(edge_session.close)


async def test_samples_are_numbered_by_tick_never_going_back() -> None:
    def tick(version: int, taken_s: float) -> Published:
        return Published(None, version, (None, None), taken_s, lambda _: b"{}")  # type: ignore[arg-type]

    sequence = Sequence(1000)
    first, second = tick(5, 1.0), tick(7, 1.1)
    assert sequence.stamp(first) == (1001, first)
    assert sequence.stamp(first) == (1001, first)  # the same tick on the other tier
    assert sequence.stamp(second) == (1002, second)
    assert sequence.stamp(first) == (1002, second)  # older: the newest is sent instead
    retaken = tick(7, 1.5)  # the same version taken again for a read: the age grew
    assert sequence.stamp(retaken) == (1003, retaken)


async def test_an_edge_that_cannot_open_zenoh_is_a_startup_error() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        endpoint = f"tcp/127.0.0.1:{taken.getsockname()[1]}"
        settings = make_settings(
            "udpout:127.0.0.1:9", zenoh=True, edge_name="edge-x", zenoh_listen=[endpoint],
            zenoh_multicast_scouting=False,
        )
        with pytest.raises(StartupError, match="cannot publish to the fleet over Zenoh"):
            async with app_running(settings):
                pass


async def test_no_log_line_carries_the_callers_token(
    edge_api: EdgeApi, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    secret = "s3cret-token-value"
    call = {"method": "POST", "path": "/api/v1/echo", "query": f"token={secret}",
            "headers": {"authorization": f"Bearer {secret}"}, "body": {}}
    reply = await edge_api.run(json.dumps(call).encode())
    assert reply["status"] == 200
    assert any("zenoh call POST /api/v1/echo" in r.getMessage() for r in caplog.records)
    assert secret not in caplog.text
    # nothing logs the call's URL (a token in its query), even where no redaction is set up
    assert not [r for r in caplog.records if r.name.startswith(("httpx", "httpcore"))]
