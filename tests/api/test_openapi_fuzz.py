"""schemathesis against /openapi.json, with a live simulated quad behind the app.

In-process (the fuzzing phase, most cases with the lease so they reach the vehicle): no 5xx,
and every response matches the documented status codes, content type and schema. Cases are
generated up front (fixed seed: derandomized hypothesis) and then sent through the ASGI
transport on the test's own event loop, where the app and the simulated vehicle run.

The schemathesis command as a user runs it, against a live `skyhelm serve`, is
tests/api/test_schemathesis_cli.py (a module of its own: the two run side by side)."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings
from schemathesis.checks import not_a_server_error
from schemathesis.core.result import Ok
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from server.app import create_app
from tests.api.conftest import PILOT, api_for, eventually, make_settings, sim_cluster

CASES_PER_OPERATION = 36
# Cases sent side by side.
LANES = 3
# Mode changes take the vehicle's two acks and a report (≈ 0.13 s each): fewer of them.
FEWER_CASES = {"/mode": 20, "/hold": 20, "/offboard/start": 20, "/offboard/stop": 20}
# Operations whose failure paths wait for vehicle timeouts (no answer to unknown parameter
# names, no ack for a VTOL transition on a quad) fuzz against an absent vehicle; their live
# behaviour is pinned by the flight and parameter tests.
# /arm is fuzzed offline too: a disarmed vehicle never flies the fuzzed setpoints.
OFFLINE_OPERATIONS = ("/params", "/vtol/transition", "/arm")
ABSENT_VEHICLE = 2
# Random generation rarely hits the schema's bounds, where projections used to break: the
# poles, the antimeridian and the altitude limits are sent to the live vehicle explicitly.
_EDGES = [(90.0, 180.0, 1.0e5), (-90.0, -180.0, -1.0e3), (0.0, 180.0, 0.0),
          (-90.0, 0.0, 1.0e5), (89.9999999, -179.9999999, -1.0e3)]
EDGE_BODIES: dict[str, list[Any]] = {
    "/origin": [{"lat_deg": lat, "lon_deg": lon, "alt_amsl_m": alt} for lat, lon, alt in _EDGES],
    "/home": [{"lat_deg": lat, "lon_deg": lon, "alt_amsl_m": alt} for lat, lon, alt in _EDGES]
    + [{"lat_deg": -90.0, "lon_deg": 180.0}],
}
# an aim() index that keeps the credentials and the lease
EDGE_CASE_INDEX = 1
# Every UNAUTHENTICATED_EVERY-th case keeps the generated credentials (mostly wrong: 401).
UNAUTHENTICATED_EVERY = 10
CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
]


def generate_cases(operation: Any, count: int) -> list[Any]:
    cases: list[Any] = []

    @settings(
        max_examples=count,
        derandomize=True,
        database=None,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
        deadline=None,
    )
    @given(operation.as_strategy())
    def collect(case: Any) -> None:
        cases.append(case)

    collect()
    return cases


def aim(case: Any, index: int, lease_id: str | None) -> None:
    """Point most cases at the live vehicle with valid credentials, so they reach the vehicle."""
    path_parameters = case.path_parameters or {}
    if "vehicle_id" in path_parameters:
        offline = any(part in case.operation.path for part in OFFLINE_OPERATIONS)
        path_parameters["vehicle_id"] = ABSENT_VEHICLE if offline else 1
    if index % UNAUTHENTICATED_EVERY == 0:
        return
    headers = case.headers if case.headers is not None else {}
    headers["Authorization"] = f"Bearer {PILOT}"
    if lease_id is not None and index % 3 != 0:
        headers["X-Lease-Id"] = lease_id
    case.headers = headers
    if case.query and "token" in case.query:
        del case.query["token"]


async def send(client: httpx.AsyncClient, case: Any) -> httpx.Response:
    kwargs = case.as_transport_kwargs(base_url="http://testserver")
    request: dict[str, Any] = {
        key: kwargs[key] for key in ("method", "url", "headers", "params") if key in kwargs
    }
    for body in ("json", "data", "content"):
        if body in kwargs:
            request["content" if body == "data" else body] = kwargs[body]
    if kwargs.get("cookies"):
        client.cookies.update(kwargs["cookies"])
    return await client.request(**request)


def generate_all() -> list[tuple[int, Any]]:
    """Every case, generated before any vehicle runs: generation is synchronous and would
    otherwise stall the event loop the app and the simulated vehicle share."""
    app = create_app(make_settings(None, connect=["udpin:127.0.0.1:0"]))
    schema = schemathesis.openapi.from_dict(app.openapi())
    cases: list[tuple[int, Any]] = []
    for result in schema.get_all_operations():
        assert isinstance(result, Ok), result
        operation = result.ok()
        count = next(
            (n for suffix, n in FEWER_CASES.items() if operation.path.endswith(suffix)),
            CASES_PER_OPERATION,
        )
        cases += enumerate(generate_cases(operation, count))
        for suffix, bodies in EDGE_BODIES.items():
            if operation.path.endswith(suffix) and operation.method.upper() == "POST":
                cases += [
                    (EDGE_CASE_INDEX, operation.Case(
                        body=body, path_parameters={"vehicle_id": 1},
                        media_type="application/json"))
                    for body in bodies
                ]
    return cases


# 150-175 s on a quiet machine of 2 cores; beside two busy loops the suite's 240 s ended it
@pytest.mark.timeout(600)
async def test_openapi_fuzz_finds_no_5xx_and_no_schema_violation() -> None:
    started = time.monotonic()
    cases = generate_all()
    generated_s = time.monotonic() - started
    # The vehicle only answers here: a slower sim leaves the CPU to the fuzzing.
    # The abuse limits (tested in test_security_*.py) would otherwise answer the fuzz's
    # wrong-credential cases by locking its address out, and later cases with 429.
    unlimited = {"lockout_free_failures": 10000, "control_rate_per_s": 1e5, "control_burst": 100000}
    async with (
        sim_cluster("quad", speed=2.0) as sim,
        api_for(sim, lease_ttl_s=60.0, **unlimited) as api,
    ):
        await api.wait_ready()
        # Modes the vehicle accepts but never reports would each wait out the 3 s confirmation;
        # the fuzz checks the API's answers, not the vehicle's timing.
        vehicle = api.app.state.api.registry.get(1)
        vehicle.mode_confirm_timeout_s = 0.3
        leases = api.app.state.api.leases
        failures: list[str] = []

        async def lane(lane_cases: list[tuple[int, Any]]) -> None:
            for index, case in lane_cases:
                if leases.current(1) is None:  # another lane may take it first: either will do
                    await api.client.post("/api/v1/vehicles/1/control", json={})
                lease = leases.current(1)
                aim(case, index, lease.lease_id if lease is not None else None)
                response = await send(api.client, case)
                try:
                    case.validate_response(response, checks=CHECKS)
                except (Exception, BaseExceptionGroup) as failure:  # a group of check failures
                    failures.append(
                        f"{case.operation.label} -> {response.status_code} {response.text}: "
                        f"{failure!r}"[:600]
                    )

        # Cases wait mostly on the vehicle's answers: a few lanes side by side, as several
        # clients of one server would send them (interleavings a single lane never makes).
        await asyncio.gather(*(lane(cases[i::LANES]) for i in range(LANES)))
        # extreme origins and homes among the cases: the vehicle must still be sending
        link = sim.instances[0].api_link
        sent_before = link.counters.tx_messages

        async def sending() -> bool:
            return link.counters.tx_messages > sent_before

        # the sim shares this loop with the fuzz's calls: on a busy machine it waits its turn
        await eventually(sending, 30.0, "telemetry from the simulated vehicle")
        assert sim.instances[0].tx_unpackable == 0
    elapsed_s = time.monotonic() - started
    operations = len({case.operation.label for _, case in cases})
    assert len(cases) >= 1000
    assert not failures, "\n".join(failures[:10])
    print(
        f"schemathesis: {len(cases)} cases over {operations} operations in {elapsed_s:.1f} s "
        f"({generated_s:.1f} s generating)"
    )
