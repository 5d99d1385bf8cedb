"""The same call through REST and through the edge's api queryable, side by side over one
app and its simulated quad: the same status and body for reads, successes, 401/403/404/405,
the lease's refusals (423, 409 held), the vehicle's 409, every kind of 422, and the same
audit entries. The edge's side is run as its queryable runs it (EdgeApi.run, what a Zenoh
query carries); Zenoh itself is test_edge.py's."""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import httpx
import pytest
import pytest_asyncio

from server.fleet.edge_api import EdgeApi
from server.fleet.edge_calls import EdgeCalls
from tests.api.conftest import OBSERVER, PILOT, Api, api_for, sim_cluster

pytestmark = pytest.mark.asyncio(loop_scope="module")

KEY = "skyhelm/parity/edge-p/api"
VEHICLE = "/api/v1/vehicles/1"
# a call the edge does not finish within this is answered 504 (an ask for control here)
CALL_TIMEOUT_S = 1.0
# what differs between two leases taken the same way: the id, how long each was held
MOVING = frozenset({"lease_id", "since_s"})


@dataclass
class Answer:
    status: int
    body: Any
    retry_after: str | None = None


@dataclass
class Both:
    api: Api
    bare: httpx.AsyncClient  # REST without the pilot's default token
    edge: EdgeApi

    async def rest(
        self, method: str, path: str, *, token: str | None = PILOT, lease: str | None = None,
        body: Any = None, query: str = "",
    ) -> Answer:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        if lease is not None:
            headers["X-Lease-Id"] = lease
        url = f"{VEHICLE}{path}" + (f"?{query}" if query else "")
        content = json.dumps(body).encode() if body is not None else None
        if content is not None:
            headers["Content-Type"] = "application/json"
        response = await self.bare.request(method, url, headers=headers, content=content)
        parsed = response.json() if response.content else None
        return Answer(response.status_code, parsed, response.headers.get("retry-after"))

    async def zenoh(
        self, method: str, path: str, *, token: str | None = PILOT, lease: str | None = None,
        body: Any = None, query: str = "",
    ) -> Answer:
        headers = {"authorization": f"Bearer {token}"} if token else {}
        if lease is not None:
            headers["x-lease-id"] = lease
        call = {"method": method, "path": f"{VEHICLE}{path}", "query": query or None,
                "headers": headers, "body": body}
        reply = await self.edge.run(json.dumps(call).encode())
        return Answer(reply["status"], reply["body"], reply["headers"].get("retry-after"))

    async def both(self, method: str, path: str, **call: Any) -> tuple[Answer, Answer]:
        return await self.rest(method, path, **call), await self.zenoh(method, path, **call)

    async def same(self, method: str, path: str, **call: Any) -> Answer:
        """The call both ways; asserts the same status and body, returns the edge's."""
        rest, edge = await self.both(method, path, **call)
        assert (edge.status, edge.body) == (rest.status, rest.body), (method, path, call)
        return edge

    async def take(self, name: str) -> str:
        taken = await self.rest("POST", "/control", body={"client_name": name})
        assert taken.status == 200, taken
        lease: str = taken.body["lease_id"]
        return lease

    async def release(self, lease: str) -> None:
        assert (await self.rest("DELETE", "/control", lease=lease)).status == 204


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def both() -> AsyncIterator[Both]:
    async with sim_cluster("quad") as sim, api_for(sim, takeover_ask_s=5.0) as api:
        await api.wait_ready()
        app = api.app
        edge = EdgeApi(
            EdgeCalls(app.state.api, app.state.publishers), KEY, call_timeout_s=CALL_TIMEOUT_S
        )
        async with httpx.AsyncClient(
            transport=httpx.ASGITransport(app=app), base_url="http://testserver", timeout=30.0
        ) as bare:
            yield Both(api, bare, edge)
        await edge.close()


async def test_reads_answer_alike(both: Both) -> None:
    for path in ("/sticks", "/control", "/params/MIS_TAKEOFF_ALT"):
        answer = await both.same("GET", path, token=OBSERVER)
        assert answer.status == 200, (path, answer)
    read = await both.same("GET", "/params", query="names=MIS_TAKEOFF_ALT,MPC_XY_VEL_MAX")
    assert set(read.body["params"]) == {"MIS_TAKEOFF_ALT", "MPC_XY_VEL_MAX"}
    # the state and the stream's figures move between two reads: the same fields
    for path in ("", "/stream"):
        rest, edge = await both.both("GET", path)
        assert (rest.status, edge.status) == (200, 200)
        assert set(edge.body) == set(rest.body)
    assert edge.body["active"] is False


async def test_refusals_before_the_call_answer_alike(both: Both) -> None:
    assert (await both.same("POST", "/arm", token=None, body={})).status == 401
    assert (await both.same("GET", "/control", token="not-a-token")).status == 401
    observer = await both.same("POST", "/arm", token=OBSERVER, body={})
    assert observer.status == 403
    assert (await both.same("POST", "/control", token=OBSERVER, body={})).status == 403
    assert (await both.same("GET", "/sticks", token=OBSERVER)).status == 200
    unknown = await both.rest("GET", "/control")
    assert unknown.status == 200
    nine_rest = await both.bare.get("/api/v1/vehicles/9/control", headers={
        "Authorization": f"Bearer {PILOT}"})
    nine_edge = await both.edge.run(json.dumps({
        "method": "GET", "path": "/api/v1/vehicles/9/control",
        "headers": {"authorization": f"Bearer {PILOT}"}}).encode())
    assert (nine_edge["status"], nine_edge["body"]) == (404, nine_rest.json())
    assert (await both.same("GET", "/arm")).status == 405
    no_lease = await both.same("POST", "/arm", body={})
    assert no_lease.status == 423
    here = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": 0.0}
    wrong_lease = await both.same("PUT", "/setpoint", lease="not-the-lease", body=here)
    assert wrong_lease.status == 423
    # the input is checked before the lease: a body the schema refuses is 422 without one
    invalid = await both.same("PUT", "/setpoint", lease="not-the-lease", body={})
    assert invalid.status == 422
    assert (await both.same("POST", "/arm", body={"force": 0})).status == 422


async def test_invalid_input_answers_422_alike(both: Both) -> None:
    lease = await both.take("parity-422")
    try:
        bad = [
            ("POST", "/takeoff", {"altitude_m": "high"}, ""),
            ("POST", "/takeoff", {"altitude_m": 10_000.0}, ""),  # above the envelope
            ("POST", "/mode", {}, ""),
            ("POST", "/mode", None, ""),
            ("PUT", "/setpoint", {"type": "nowhere"}, ""),
            ("PUT", "/setpoint", {"type": "velocity_ned", "north_m_s": 0.0, "east_m_s": 0.0,
                                  "down_m_s": 0.0}, "live=maybe"),
            ("PUT", "/sticks", {"pitch": 3.0}, ""),
            ("PUT", "/params/NOT-A-NAME", {"value": 1.0}, ""),
            ("GET", "/params", None, "names=A,B-C"),
            ("POST", "/control", {"ttl_s": 100_000.0}, ""),
            ("POST", "/control", {"client_pid": 0}, ""),
            ("POST", "/control/requests/x", None, ""),
            ("POST", "/intents/goto", {"lat_deg": 91.0, "lon_deg": 0.0}, ""),
        ]
        for method, path, body, query in bad:
            answer = await both.same(method, path, lease=lease, body=body, query=query)
            assert answer.status == 422, (method, path, answer)
    finally:
        await both.release(lease)


async def test_the_lease_and_the_vehicle_refuse_alike(both: Both) -> None:
    lease = await both.take("alice")
    try:
        held = await both.same("POST", "/control", body={"client_name": "bob"})
        assert held.status == 409
        assert held.body["detail"]["holder"] == "pilot · alice"
        stale = await both.same("PUT", "/control", lease="gone-lease", body={})
        assert stale.status == 423
        rest, edge = await both.both(
            "POST", "/vtol/transition", lease=lease, body={"to": "fixed_wing", "wait": False}
        )
        assert (rest.status, edge.status) == (409, 409)
        for answer in (rest, edge):
            answer.body.pop("elapsed_ms")
        assert edge.body == rest.body
        assert edge.body["result"] == "FAILED"
        # an ask for control the holder leaves unanswered past the edge's call timeout: 504,
        # and the ask is withdrawn (REST's holder sees no request pending)
        asked = await both.zenoh("POST", "/control", body={"client_name": "bob",
                                                             "takeover": True})
        assert asked.status == 504, asked
        assert "did not finish" in asked.body["detail"]["reason"]
        status = await both.rest("GET", "/control")
        assert status.body["holder"] == "pilot · alice"
        assert status.body["request"] is None
    finally:
        await both.release(lease)


async def test_success_and_the_audit_entries_are_alike(both: Both) -> None:
    audit = both.api.app.state.api.audit

    async def acquire_and_release(via: str) -> tuple[Answer, Answer, list[dict[str, Any]]]:
        before = len(audit.entries(1, 1000))
        run = both.rest if via == "rest" else both.zenoh
        taken = await run("POST", "/control", body={"client_name": "parity", "ttl_s": 7.0})
        assert taken.status == 200, taken
        lease = taken.body["lease_id"]
        renewed = await run("PUT", "/control", lease=lease, body={"ttl_s": 8.0})
        hold = await run("POST", "/hold", lease=lease)
        assert hold.status == 200, hold
        hold.body.pop("elapsed_ms")
        released = await run("DELETE", "/control", lease=lease)
        assert (released.status, released.body) == (204, None)
        entries = [
            {"kind": e["kind"], **{k: v for k, v in e["data"].items() if k not in MOVING}}
            for e in audit.entries(1, 1000)[before:]
        ]
        renewed.body.pop("lease_id")
        return renewed, hold, entries

    rest_renewed, rest_hold, rest_entries = await acquire_and_release("rest")
    edge_renewed, edge_hold, edge_entries = await acquire_and_release("edge")
    assert edge_renewed.status == rest_renewed.status == 200
    assert set(edge_renewed.body) == set(rest_renewed.body)
    for key in ("holder", "session", "ttl_s", "setpoint", "taken_from"):
        assert edge_renewed.body[key] == rest_renewed.body[key], key
    assert edge_renewed.body["holder"] == "pilot · parity"
    assert edge_hold == rest_hold
    assert rest_entries, "acquire and release are audited"
    assert [e["kind"] for e in rest_entries] == [e["kind"] for e in edge_entries]
    assert edge_entries == rest_entries
