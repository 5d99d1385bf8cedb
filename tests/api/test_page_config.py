"""The page's configuration: the 2D map's tile URL, behind the token, checked at start."""

from __future__ import annotations

import httpx
import pytest

from server.settings import SettingsError, load_settings, tile_origin
from tests.api.conftest import OBSERVER, api_for, auth

TILES = "https://{s}.tile.example.org/{z}/{x}/{y}.png"


async def test_config_gives_the_tile_url_to_observers_and_not_without_a_token() -> None:
    async with api_for(
        None, connect=["udpin:127.0.0.1:0"], map_tile_url=TILES, map_tile_attribution="© Example"
    ) as api:
        answer = await api.client.get("/api/v1/config", headers=auth(OBSERVER))
        assert answer.status_code == 200
        assert answer.json() == {
            "map_tile_url": TILES, "map_tile_attribution": "© Example", "fleet": False,
            "map_tiles_offline": False, "map_tile_min_zoom": None, "map_tile_max_zoom": None,
            "map_tile_bounds": None, "scene": False,
        }
        async with httpx.AsyncClient(
            transport=httpx.ASGITransport(app=api.app), base_url="http://testserver"
        ) as anonymous:
            assert (await anonymous.get("/api/v1/config")).status_code == 401


async def test_config_without_tiles_says_null() -> None:
    async with api_for(None, connect=["udpin:127.0.0.1:0"]) as api:
        answer = await api.client.get("/api/v1/config")
        assert answer.json()["map_tile_url"] is None


@pytest.mark.parametrize("scene", [True, False])
async def test_config_says_whether_the_scene_is_served(scene: bool) -> None:
    async with api_for(None, connect=["udpin:127.0.0.1:0"], scene=scene) as api:
        assert (await api.client.get("/api/v1/config")).json()["scene"] is scene


@pytest.mark.parametrize(
    ("url", "reason"),
    [
        ("ftp://tiles.example.org/{z}/{x}/{y}.png", "http(s)"),
        ("https:///{z}/{x}/{y}.png", "host"),
        ("https://tiles.example.org/{z}/{x}.png", "{y}"),
        ("javascript:alert(1)//{z}/{x}/{y}", "http(s)"),
    ],
)
def test_a_tile_url_without_scheme_host_or_placeholders_is_refused(url: str, reason: str) -> None:
    with pytest.raises(SettingsError, match="map_tile_url") as refused:
        load_settings(map_tile_url=url)
    assert reason in str(refused.value)


def test_an_empty_tile_url_means_the_offline_grid() -> None:
    assert load_settings(map_tile_url="  ").map_tile_url is None


@pytest.mark.parametrize(
    ("url", "origin"),
    [
        (TILES, "https://*.tile.example.org"),
        ("http://127.0.0.1:8080/tiles/{z}/{x}/{y}.png", "http://127.0.0.1:8080"),
        (None, None),
    ],
)
def test_tile_origin_is_what_img_src_must_allow(url: str | None, origin: str | None) -> None:
    assert tile_origin(url) == origin
