"""Who may do what, and how refusals look: 401/403/404/422/423, CORS, health without a token.
These need no vehicle: the registry is empty and no simulated vehicle is started."""

from __future__ import annotations

from collections.abc import AsyncIterator

import httpx
import pytest

from server.control.auth import TokenChecker
from tests.api.conftest import OBSERVER, PILOT, Api, api_for, auth


@pytest.fixture
async def empty_api() -> AsyncIterator[Api]:
    # connect to a port nobody answers on: the app runs with no vehicle at all
    async with api_for(None, connect=["udpin:127.0.0.1:0"]) as api:
        yield api


async def test_health_needs_no_token(empty_api: Api) -> None:
    response = await empty_api.client.get("/api/v1/health", headers={"Authorization": ""})
    assert response.status_code == 200
    assert response.json()["status"] == "ok"
    assert response.json()["vehicles"] == 0


@pytest.mark.parametrize(
    "headers",
    [{}, {"Authorization": "Bearer wrong-token-value"}, {"Authorization": "Basic " + PILOT}],
)
async def test_reads_without_a_valid_token_are_401(empty_api: Api, headers: dict[str, str]) -> None:
    async with httpx.AsyncClient(
        transport=httpx.ASGITransport(app=empty_api.app), base_url="http://testserver"
    ) as anonymous:
        response = await anonymous.get("/api/v1/vehicles", headers=headers)
    assert response.status_code == 401
    assert response.json()["detail"]["reason"] == "missing or wrong token"


async def test_token_in_query_is_accepted(empty_api: Api) -> None:
    async with httpx.AsyncClient(
        transport=httpx.ASGITransport(app=empty_api.app), base_url="http://testserver"
    ) as anonymous:
        response = await anonymous.get("/api/v1/vehicles", params={"token": OBSERVER})
    assert response.status_code == 200
    assert response.json() == []


async def test_observer_may_read_but_not_control(empty_api: Api) -> None:
    client = empty_api.client
    assert (await client.get("/api/v1/vehicles", headers=auth(OBSERVER))).status_code == 200
    response = await client.post("/api/v1/vehicles/1/arm", json={}, headers=auth(OBSERVER))
    assert response.status_code == 403
    response = await client.post("/api/v1/vehicles/1/control", json={}, headers=auth(OBSERVER))
    assert response.status_code == 403


async def test_unknown_vehicle_is_404(empty_api: Api) -> None:
    for response in (
        await empty_api.client.get("/api/v1/vehicles/7"),
        await empty_api.client.get("/api/v1/vehicles/7/stream"),
        await empty_api.client.post("/api/v1/vehicles/7/control", json={}),
    ):
        assert response.status_code == 404
        assert response.json()["detail"]["reason"] == "no vehicle 7"


async def test_a_documented_path_asked_with_another_method_is_405_with_its_methods(
    empty_api: Api,
) -> None:
    response = await empty_api.client.put("/api/v1/vehicles/7/arm", json={})
    assert response.status_code == 405
    assert response.headers["allow"] == "POST"
    response = await empty_api.client.get("/api/v1/no-such-call")
    assert response.status_code == 404


async def test_cors_is_closed_by_default(empty_api: Api) -> None:
    response = await empty_api.client.options(
        "/api/v1/vehicles",
        headers={"Origin": "https://evil.example", "Access-Control-Request-Method": "GET"},
    )
    assert "access-control-allow-origin" not in response.headers


async def test_configured_cors_origin_is_allowed() -> None:
    origin = "https://ops.example"
    async with api_for(None, connect=["udpin:127.0.0.1:0"], cors_origins=[origin]) as api:
        response = await api.client.options(
            "/api/v1/vehicles",
            headers={"Origin": origin, "Access-Control-Request-Method": "GET"},
        )
    assert response.headers["access-control-allow-origin"] == origin


def test_token_checker_tells_pilot_from_observer() -> None:
    checker = TokenChecker(PILOT, OBSERVER)
    assert checker.role_of(PILOT) is not None
    assert checker.role_of(PILOT) != checker.role_of(OBSERVER)
    assert checker.role_of(PILOT[:-1]) is None
    assert checker.role_of(None) is None
    assert checker.role_of("") is None
