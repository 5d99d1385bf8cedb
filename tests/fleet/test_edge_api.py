"""The edge's api queryable over an edge with no vehicle: what of a query counts (the
caller's token and lease, from the address ``zenoh``), what of an answer goes back, and the
answers the edge gives itself (bad path or payload, too many at once), over real Zenoh on
loopback; and how the edge numbers a vehicle's state samples. The same calls with a
vehicle, next to REST: test_edge_parity.py."""

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

from server.app import StartupError, create_app
from server.control.publisher import Published
from server.fleet.edge_api import EdgeApi, check_path
from server.fleet.edge_calls import ZENOH_ADDRESS, EdgeCalls
from server.fleet.edge_publish import Sequence
from server.fleet.proxy import call_timeout_s
from server.fleet.session import open_session
from server.http.context import ApiContext
from server.http.vehicle_calls import CALLS
from tests.api.conftest import OBSERVER, PILOT, app_running, make_settings
from tests.fleet.fake_edge import free_tcp_endpoint, loopback_options
from tests.waiting import eventually

pytestmark = pytest.mark.asyncio(loop_scope="module")

KEY = "skyhelm/apitest/edge-u/api"


def no_vehicle_calls(**overrides: Any) -> EdgeCalls:
    """The calls of an app linked to nowhere (its lifespan not run: no vehicle)."""
    app = create_app(make_settings("udpout:127.0.0.1:9", **overrides))
    return EdgeCalls(app.state.api, app.state.publishers)


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def edge_api() -> AsyncIterator[EdgeApi]:
    api = EdgeApi(no_vehicle_calls(), KEY, call_timeout_s=0.5)
    yield api
    await api.close()


def _call(method: str, path: str, token: str | None = PILOT, **more: Any) -> bytes:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    return json.dumps({"method": method, "path": path, "headers": headers, **more}).encode()


async def test_only_the_callers_bearer_token_counts_and_wrong_ones_lock_out_zenoh() -> None:
    calls = no_vehicle_calls(lockout_free_failures=2, lockout_base_s=60.0)
    api = EdgeApi(calls, KEY)
    try:
        # a cookie or an Origin is not the caller's authority here: no token at all
        cookie = {"method": "GET", "path": "/api/v1/vehicles/1/control",
                  "headers": {"Cookie": f"skyhelm_token={PILOT}", "Origin": "http://x"}}
        missing = await api.run(json.dumps(cookie).encode())
        assert missing["status"] == 401, missing
        assert missing["headers"]["www-authenticate"] == "Bearer"
        assert missing["body"] == {"detail": {"reason": "missing or wrong token"}}
        known = await api.run(_call("GET", "/api/v1/vehicles/1/control", OBSERVER))
        assert known["status"] == 404  # the token is right; there is no vehicle 1
        assert known["body"] == {"detail": {"reason": "no vehicle 1"}}
        for _ in range(3):  # the third wrong token past the free ones locks the address
            assert (await api.run(_call("GET", "/api/v1/vehicles/1", "wrong")))["status"] == 401
        context: ApiContext = calls.context
        assert context.guards.lockout.failures(ZENOH_ADDRESS) == 3
        locked = await api.run(_call("GET", "/api/v1/vehicles/1", "wrong"))
        assert locked["status"] == 429, locked
        assert int(locked["headers"]["retry-after"]) >= 1
        # while locked out even the right token waits, as it does over REST
        assert (await api.run(_call("GET", "/api/v1/vehicles/1")))["status"] == 429
    finally:
        await api.close()


async def test_control_calls_share_the_tokens_rate_limit() -> None:
    api = EdgeApi(no_vehicle_calls(control_rate_per_s=0.01, control_burst=2), KEY)
    try:
        statuses = [(await api.run(_call("POST", "/api/v1/vehicles/1/arm", body={})))["status"]
                    for _ in range(3)]
        assert statuses == [404, 404, 429]
        limited = await api.run(_call("POST", "/api/v1/vehicles/1/arm", body={}))
        assert limited["body"]["detail"]["reason"].startswith("rate limit")
        assert "retry-after" in limited["headers"]
        # reads are not control calls
        assert (await api.run(_call("GET", "/api/v1/vehicles/1")))["status"] == 404
    finally:
        await api.close()


async def test_what_the_edge_does_not_offer_is_404_and_a_wrong_method_405(
    edge_api: EdgeApi,
) -> None:
    for path in ("/api/v1/vehicles", "/api/v1/health", "/api/v1/signing",
                 "/api/v1/control/audit", "/api/v1/vehicles/1/nothing-here"):
        reply = await edge_api.run(_call("GET", path))
        assert reply["status"] == 404, (path, reply)
        assert reply["body"]["detail"]["field"] == "path"
    wrong = await edge_api.run(_call("GET", "/api/v1/vehicles/1/arm"))
    assert wrong["status"] == 405
    assert wrong["body"] == {"detail": "Method Not Allowed"}
    assert wrong["headers"] == {"content-type": "application/json"}


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
        (b'{"method": "POST", "path": "/api/v1/vehicles/1/arm", "body": NaN}', 422, "body"),
        (b'{"method": "PUT", "path": "/api/v1/vehicles/1/setpoint", "body": {"x": [1, NaN]}}',
         422, "body"),
        (b"{" + b" " * (1 << 20) + b"}", 413, "payload"),
    ],
)
async def test_what_is_not_a_call_is_answered_with_why(
    edge_api: EdgeApi, payload: bytes, status: int, field: str
) -> None:
    reply = await edge_api.run(payload)
    assert reply["status"] == status, reply
    assert reply["body"]["detail"]["field"] == field


async def test_a_read_has_5_s_a_command_15_s_and_an_ask_the_holders_time_on_top() -> None:
    ask = {"takeover": True, "client_name": "me"}
    assert call_timeout_s("GET", "state", None, takeover_ask_s=10.0) == 5.0
    assert call_timeout_s("GET", "state", None, 10.0, base_s=1.0) == 1.0
    assert call_timeout_s("POST", "control", ask, takeover_ask_s=10.0) == 25.0
    assert call_timeout_s("POST", "control", ask, takeover_ask_s=3.0, base_s=20.0) == 23.0
    # answered without waiting for a holder: a forced takeover, a plain acquire, anything else
    assert call_timeout_s("POST", "control", {**ask, "force": True}, 10.0) == 15.0
    assert call_timeout_s("POST", "control", {}, 10.0) == 15.0
    assert call_timeout_s("POST", "control", None, 10.0) == 15.0
    assert call_timeout_s("PUT", "control", ask, 10.0) == 15.0
    assert call_timeout_s("POST", "offboard/start", ask, 10.0) == 15.0


async def test_paths_under_the_api_only() -> None:
    check_path("/api/v1/vehicles/1/params/MPC_XY_VEL_MAX")
    check_path("/api/v1/vehicles/1/arm")


async def test_every_query_is_answered_even_when_busy_or_stopping() -> None:
    endpoint = free_tcp_endpoint()
    edge_session = await asyncio.to_thread(open_session, loopback_options(listen=[endpoint]))
    caller = await asyncio.to_thread(open_session, loopback_options(connect=[endpoint]))
    api = EdgeApi(no_vehicle_calls(), KEY, max_in_flight=0)
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
    call = {"method": "POST", "path": "/api/v1/vehicles/1/arm", "query": f"token={secret}",
            "headers": {"authorization": f"Bearer {secret}"}, "body": {}}
    reply = await edge_api.run(json.dumps(call).encode())
    assert reply["status"] == 401
    assert any("zenoh call POST /api/v1/vehicles/1/arm" in r.getMessage()
               for r in caplog.records)
    assert secret not in caplog.text
    # nothing logs the call's URL (a token in its query), even where no redaction is set up
    assert not [r for r in caplog.records if r.name.startswith(("httpx", "httpcore"))]


async def test_every_rest_call_under_a_vehicle_is_one_the_edge_runs() -> None:
    """A route added under /vehicles/{vehicle_id} is added to the edge's table too."""
    app = create_app(make_settings("udpout:127.0.0.1:9"))
    prefix = "/api/v1/vehicles/{vehicle_id}"
    rest = {
        (method.upper(), path.removeprefix(prefix).removeprefix("/"))
        for path, operations in app.openapi()["paths"].items()
        if path.startswith(prefix)
        for method in operations
    }
    offered = {(call.method, call.path) for call in CALLS}
    assert len(rest) > 30
    assert rest == offered
