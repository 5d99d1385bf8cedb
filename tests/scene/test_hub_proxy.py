"""The scene hub behind the app's port: page, socket and scene API through the proxy."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import httpx
import msgspec
import pytest
import viser
import websockets
import zstandard
from fastapi import FastAPI
from websockets.asyncio.client import connect
from websockets.typing import Subprotocol

from server.scene.hub import SceneHub
from server.scene.proxy import pace_script
from skyhelm_wire.messages import SceneClickMessage
from tests.api.state_fakes import PushingVehicle, pushing, scene_fed_by
from tests.serving import uvicorn_serving
from tests.waiting import wait_for

from .conftest import FakeVehicle

TOKEN = "scene-test-token"
SUBPROTOCOL = Subprotocol(f"viser-v{viser.__version__}")


@dataclass
class Served:
    hub: SceneHub
    base: str
    vehicles: list[PushingVehicle]


@pytest.fixture
async def served() -> AsyncIterator[Served]:
    vehicles = [pushing(FakeVehicle(1)), pushing(FakeVehicle(2, "VTOL_FIXEDROTOR"))]
    hub = SceneHub(max_rate_hz=20.0)
    app = FastAPI()
    hub.mount(app, check_token=lambda token: token == TOKEN)
    async with scene_fed_by(hub, vehicles), uvicorn_serving(app) as host:
        yield Served(hub, host, vehicles)


async def test_scene_page_is_served_with_token_and_sets_scene_cookie(served: Served) -> None:
    async with httpx.AsyncClient(base_url=f"http://{served.base}") as client:
        page = await client.get("/scene/", params={"token": TOKEN})
        assert page.status_code == 200
        assert page.headers["content-type"].startswith("text/html")
        assert "<html" in page.text.lower()
        cookie = page.headers["set-cookie"]
        assert "skyhelm_token=" in cookie
        assert "Path=/scene" in cookie
        assert "HttpOnly" in cookie
        redirect = await client.get("/scene", params={"token": TOKEN})
        assert redirect.status_code == 307
        assert redirect.headers["location"] == f"/scene/?token={TOKEN}"


@pytest.mark.parametrize("token", [None, "wrong"])
async def test_scene_page_and_api_refuse_missing_or_wrong_token(served: Served,
                                                                token: str | None) -> None:
    params = {"token": token} if token else {}
    async with httpx.AsyncClient(base_url=f"http://{served.base}") as client:
        assert (await client.get("/scene/", params=params)).status_code == 401
        assert (await client.get("/scene/api/click", params=params)).status_code == 401
        bearer = await client.get("/scene/api/status", headers={"Authorization": f"Bearer {TOKEN}"})
        assert bearer.status_code == 200


async def test_viser_socket_works_through_the_app_port_with_the_cookie(served: Served) -> None:
    async with connect(f"ws://{served.base}/scene", subprotocols=[SUBPROTOCOL],
                       additional_headers={"Cookie": f"skyhelm_token={TOKEN}"},
                       max_size=None) as ws:
        assert ws.subprotocol == SUBPROTOCOL
        first = await asyncio.wait_for(ws.recv(), 10.0)
        assert isinstance(first, bytes)
        assert len(first) > 0
        async with httpx.AsyncClient(base_url=f"http://{served.base}") as client:
            status = (await client.get("/scene/api/status", params={"token": TOKEN})).json()
        assert status["proxied_sockets"] == 1
        assert status["vehicles"] == [1, 2]


@pytest.mark.parametrize(
    ("cookie", "origin", "code"),
    [
        (None, None, 4401),
        ("skyhelm_token=wrong", None, 4401),
        (f"skyhelm_token={TOKEN}", "http://evil.example", 4403),
    ],
)
async def test_viser_socket_refused_without_the_token_or_from_another_origin(
    served: Served, cookie: str | None, origin: str | None, code: int
) -> None:
    headers = {"Cookie": cookie} if cookie else {}
    async with connect(f"ws://{served.base}/scene", subprotocols=[SUBPROTOCOL],
                       additional_headers=headers,
                       origin=websockets.typing.Origin(origin) if origin else None) as ws:
        with pytest.raises(websockets.exceptions.ConnectionClosed) as closed:
            await asyncio.wait_for(ws.recv(), 10.0)
    assert closed.value.rcvd is not None
    assert closed.value.rcvd.code == code


async def test_scene_updates_stay_under_the_rate_limit_per_vehicle(served: Served) -> None:
    async with connect(f"ws://{served.base}/scene", subprotocols=[SUBPROTOCOL],
                       additional_headers={"Cookie": f"skyhelm_token={TOKEN}"},
                       max_size=None) as ws:
        await asyncio.wait_for(ws.recv(), 10.0)
        start = served.hub.updates_applied
        t0 = time.monotonic()
        received = 0
        while time.monotonic() - t0 < 1.5:
            try:
                await asyncio.wait_for(ws.recv(), 0.1)
                received += 1
            except TimeoutError:
                pass
        elapsed = time.monotonic() - t0
    per_vehicle_hz = (served.hub.updates_applied - start) / 2 / elapsed
    assert per_vehicle_hz <= 20.0 * 1.1
    assert per_vehicle_hz >= 4.0
    assert received > 0


async def test_an_unwatched_scene_asks_for_states_at_its_idle_rate() -> None:
    """Nobody watching: the scene follows every vehicle at the idle rate (2 Hz), and asks
    their publishers for no more, so they take ~2 snapshots a second, not 20."""
    vehicles = [pushing(FakeVehicle(1)), pushing(FakeVehicle(2))]
    hub = SceneHub(max_rate_hz=20.0)
    async with scene_fed_by(hub, vehicles) as publishers:
        feeds = [publishers.for_vehicle(v) for v in vehicles]  # type: ignore[arg-type]
        await wait_for(lambda: hub.updates_applied >= 2, 10.0, "first scene updates")
        applied, ticks = hub.updates_applied, [feed.ticks for feed in feeds]
        t0 = time.monotonic()
        await asyncio.sleep(2.0)
        elapsed = time.monotonic() - t0
        applied_hz = (hub.updates_applied - applied) / len(vehicles) / elapsed
        snapshots_hz = [(feed.ticks - n) / elapsed for feed, n in zip(feeds, ticks, strict=True)]
    assert 0.5 <= applied_hz <= 2.0 * 1.5
    assert all(hz <= 2.0 * 1.5 for hz in snapshots_hz), snapshots_hz


async def test_click_endpoint_reports_the_ground_point_with_lat_lon(served: Served) -> None:
    async with httpx.AsyncClient(base_url=f"http://{served.base}") as client:
        assert (await client.get("/scene/api/click", params={"token": TOKEN})).json() == {"seq": 0}
        await wait_for(lambda: served.hub.status()["vehicles"] == [1, 2], 5.0, "both vehicles")
        pushed: list[SceneClickMessage] = []
        served.hub.on_click = pushed.append
        served.hub.record_click((0.0, -20.0, 10.0), (0.0, 1.0, -0.5))
        click = (await client.get("/scene/api/click", params={"token": TOKEN})).json()
    assert [point.seq for point in pushed] == [1]
    assert click["seq"] == 1
    assert click["north_m"] == pytest.approx(0.0, abs=1e-6)
    assert click["east_m"] == pytest.approx(0.0, abs=1e-6)
    assert click["lat_deg"] == pytest.approx(47.397742, abs=1e-7)
    assert click["lon_deg"] == pytest.approx(8.545594, abs=1e-7)
    # what the telemetry socket sends of it is the wire's scene_click message
    message = {"type": "scene_click", **click}
    assert SceneClickMessage.model_validate(message).model_dump() == message


async def test_the_scene_page_carries_the_pacing_script_first_and_assets_pass_as_asked(
        served: Served) -> None:
    async with httpx.AsyncClient(base_url=f"http://{served.base}") as client:
        page = await client.get("/scene/", params={"token": TOKEN},
                                headers={"Accept-Encoding": "gzip"})
        assert page.status_code == 200
        head = page.text.lower().split("<head>", 1)[1]
        assert head.startswith("<script>")
        assert head.index("skyhelmscenepace") < head.index("</script>")
        # the only change: viser's page without the script is byte for byte viser's own
        upstream = await client.get(f"http://127.0.0.1:{served.hub.port}/")
        assert page.content.replace(pace_script(), b"") == upstream.content


async def test_the_scene_is_lit_without_an_environment_map(served: Served) -> None:
    """Viser's default environment map (an HDRI, prefiltered on the client) kept a page's
    software WebGL at 60 % of a core for ~40 s after the view showed, 22 CPU-s in its first
    minute against 12 without it: the scene asks none, and a hemisphere light lights it."""
    async with connect(f"ws://{served.base}/scene", subprotocols=[SUBPROTOCOL],
                       additional_headers={"Cookie": f"skyhelm_token={TOKEN}"},
                       max_size=None) as ws:
        seen: dict[str, list[dict[str, Any]]] = {}
        while "HemisphereLightMessage" not in seen:
            for message in _viser_messages(await asyncio.wait_for(ws.recv(), 10.0)):
                seen.setdefault(str(message.get("type")), []).append(message)
    environment = seen["EnvironmentMapMessage"][-1]  # the one in force
    assert environment["hdri_data"] is None, sorted(environment)
    (light,) = seen["HemisphereLightMessage"]
    assert light["props"]["intensity"] > 0, light


def _viser_messages(frame: bytes | str) -> list[dict[str, Any]]:
    """The messages of one of viser's socket frames: 8 bytes the msgpack's size, 8 bytes its
    zstd-compressed size, the compressed msgpack, then binary buffers."""
    assert isinstance(frame, bytes)
    size, packed = int.from_bytes(frame[:8], "little"), int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16:16 + packed], max_output_size=size)
    messages: list[dict[str, Any]] = msgspec.msgpack.decode(inner)["messages"]
    return messages
