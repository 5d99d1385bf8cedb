"""Fixtures: an in-process simulated vehicle (faster than real time), the app connected to it,
an httpx client through ASGI, and a real uvicorn on an ephemeral port for WebSocket tests."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

import httpx
import pytest
from fastapi import FastAPI

from server.app import create_app
from server.link import Vehicle
from server.settings import Settings, load_settings
from sim.process.runner import SimCluster, SimInstance
from tests.waiting import eventually

PILOT = "pilot-token-for-tests"
OBSERVER = "observer-token-for-tests"
# Sim seconds per wall second; PX4 timeouts inside the sim scale with it.
SIM_SPEED = 8.0


def make_settings(url: str | None, **overrides: Any) -> Settings:
    values: dict[str, Any] = {
        "connect": [url] if url else [],
        "token": PILOT,
        "observer_token": OBSERVER,
        "scene": False,
        "log_dir": None,
        "web_dir": None,
    }
    values.update(overrides)
    return load_settings(**values)


def auth(token: str = PILOT) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


@dataclass
class Api:
    """The app, a pilot client, and the simulated vehicle behind it."""

    app: FastAPI
    client: httpx.AsyncClient
    sim: SimCluster | None
    lease_headers: dict[str, str] = field(default_factory=dict)
    # the vehicle the calls below mean when given none (PX4 SITL instance N is N + 1)
    default_vehicle: int = 1

    @property
    def inst(self) -> SimInstance:
        assert self.sim is not None
        return self.sim.instances[0]

    def vehicle(self, vehicle_id: int = 1) -> Vehicle:
        """The server's own vehicle object, for what the API does not show (stream stats)."""
        vehicle: Vehicle | None = self.app.state.api.registry.get(vehicle_id)
        assert vehicle is not None, f"no vehicle {vehicle_id}"
        return vehicle

    async def state(self, vehicle_id: int | None = None) -> dict[str, Any]:
        vehicle_id = vehicle_id or self.default_vehicle
        response = await self.client.get(f"/api/v1/vehicles/{vehicle_id}")
        assert response.status_code == 200, response.text
        result: dict[str, Any] = response.json()
        return result

    async def take_control(
        self, vehicle_id: int | None = None, ttl_s: float | None = None
    ) -> dict[str, str]:
        vehicle_id = vehicle_id or self.default_vehicle
        body = {} if ttl_s is None else {"ttl_s": ttl_s}
        response = await self.client.post(f"/api/v1/vehicles/{vehicle_id}/control", json=body)
        assert response.status_code == 200, response.text
        self.lease_headers = {"X-Lease-Id": response.json()["lease_id"]}
        return self.lease_headers

    async def control(
        self, path: str, body: Any = None, vehicle_id: int | None = None
    ) -> httpx.Response:
        """A control call with the lease (POST, or PUT for the setpoint)."""
        vehicle_id = vehicle_id or self.default_vehicle
        url = f"/api/v1/vehicles/{vehicle_id}/{path}"
        if path == "setpoint":
            return await self.client.put(url, json=body, headers=self.lease_headers)
        return await self.client.post(url, json=body, headers=self.lease_headers)

    async def wait_state(
        self,
        predicate: Callable[[dict[str, Any]], bool],
        timeout_s: float,
        what: str,
        *,
        renew: bool = True,
    ) -> dict[str, Any]:
        """Poll the state; a pilot holding the lease keeps renewing it while waiting."""

        last: dict[str, Any] | None = None

        async def probe() -> dict[str, Any] | None:
            nonlocal last
            if renew and self.lease_headers:
                await self.client.put(f"/api/v1/vehicles/{self.default_vehicle}/control",
                                      headers=self.lease_headers)
            last = await self.state()
            return last if predicate(last) else None

        try:
            result: dict[str, Any] = await eventually(probe, timeout_s, what)
        except AssertionError as timed_out:
            raise AssertionError(f"{timed_out}; the last state: {_summary(last)}") from None
        return result

    async def wait_ready(self) -> None:
        """Vehicle seen, with a global position and a home: able to arm."""
        await self.wait_state(
            lambda s: s["global"] is not None and s["home"] is not None, 10.0, "position and home"
        )


def _summary(state: dict[str, Any] | None) -> str:
    """What a failed wait shows of the last state: the fields a wait is usually about."""
    if state is None:
        return "none read"
    keys = ("connected", "armed", "mode", "landed_state", "stream", "link_quality",
            "position_ned")
    return repr({key: state[key] for key in keys if key in state})


@contextlib.asynccontextmanager
async def app_running(settings: Settings) -> AsyncIterator[FastAPI]:
    app = create_app(settings)
    async with app.router.lifespan_context(app):
        yield app


@contextlib.asynccontextmanager
async def api_for(sim: SimCluster | None, **overrides: Any) -> AsyncIterator[Api]:
    url = f"udpout:127.0.0.1:{sim.instances[0].api_local_port}" if sim else None
    async with api_at(url, sim, **overrides) as api:
        yield api


@contextlib.asynccontextmanager
async def api_at(
    url: str | None, sim: SimCluster | None, *, client_timeout_s: float = 30.0,
    appear_within_s: float = 10.0, **overrides: Any,
) -> AsyncIterator[Api]:
    """SkyHelm's app linked to `url` (none: no vehicle) with a pilot client over ASGI,
    yielded once the vehicle shows in /vehicles."""
    async with app_running(make_settings(url, **overrides)) as app:
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(
            transport=transport, base_url="http://testserver", headers=auth(),
            timeout=client_timeout_s,
        ) as client:
            api = Api(app, client, sim)
            if url is not None:
                await eventually(
                    lambda: _has_vehicle(client), appear_within_s,
                    "the vehicle to appear in /vehicles",
                )
            yield api


async def _has_vehicle(client: httpx.AsyncClient) -> bool:
    response = await client.get("/api/v1/vehicles")
    return bool(response.json())


@contextlib.asynccontextmanager
async def sim_cluster(
    airframe: str = "quad", speed: float = SIM_SPEED
) -> AsyncIterator[SimCluster]:
    async with SimCluster(airframe=airframe, count=1, speed=speed) as sim:
        with sim.fast_forwarded():  # its estimator's start, which no test looks at
            await sim.wait_ready(timeout_s=30.0)
        yield sim


@pytest.fixture
async def quad_api() -> AsyncIterator[Api]:
    async with sim_cluster("quad") as sim, api_for(sim) as api:
        await api.wait_ready()
        yield api
