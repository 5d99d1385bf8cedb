"""The offline map in a Chromium that can reach nothing but loopback: `skyhelm serve
--map-tiles` with an archive this test makes, and the page's map drawing its tiles, every
one fetched from the server."""

from __future__ import annotations

from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from tests.map_tiles import make_archive

from .flows import open_dashboard
from .harness import Serve, wait_for

# every host name fails to resolve and everything not on loopback goes to a proxy that is
# not there (Chromium never sends loopback through a proxy): no network but this machine
LOOPBACK_ONLY_ARGS = [
    "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
    "--proxy-server=http://127.0.0.1:9",
]
TILE_PATH = "/api/v1/tiles/"


BROWSER_ARGS = LOOPBACK_ONLY_ARGS
VIEWPORT = {"width": 1280, "height": 800}


def SERVE_ARGS(directory: Path) -> list[str]:
    """The archive this module's server serves, made in `directory`."""
    archive = directory / "field.pmtiles"
    make_archive(archive, zooms=range(17, 20), reach=4, attribution="Field map", tile_px=256)
    return ["--sim-speed", "3", "--map-tiles", str(archive)]


def test_the_map_shows_the_archives_tiles_with_no_network(browser: Any, serve: Serve) -> None:
    requests: list[str] = []
    tiles: dict[str, int] = {}
    browser.on("request", lambda r: requests.append(r.url))
    browser.on(
        "response", lambda r: tiles.__setitem__(r.url, r.status) if TILE_PATH in r.url else None
    )
    page = open_dashboard(browser, serve.url, scene=False)
    try:
        page.wait_for_selector(".map-vehicle", timeout=30_000)
        page.wait_for_function(
            "document.querySelectorAll('#map img.leaflet-tile-loaded').length >= 4",
            timeout=20_000,
        )
        loaded = page.eval_on_selector_all(
            "#map img.leaflet-tile-loaded",
            "imgs => imgs.map(i => ({src: i.src, w: i.naturalWidth, done: i.complete}))",
        )
        # drawn from the server's archive: decoded images, the map's zoom
        assert loaded
        assert all(TILE_PATH in t["src"] and t["done"] and t["w"] == 256 for t in loaded), loaded
        assert any("/18/" in t["src"] for t in loaded)  # the map opens at zoom 18
        wait_for("tile answers", lambda: any(s == 200 for s in tiles.values()), 10.0)
        assert set(tiles.values()) <= {200, 304}, tiles
        assert page.locator("path.map-grid").count() == 0
        assert "Field map" in (page.text_content(".leaflet-control-attribution") or "")
        # nothing left this machine
        hosts = {urlsplit(u).hostname for u in requests if u.startswith("http")}
        assert hosts == {"127.0.0.1"}, hosts
    finally:
        page.close()


def test_a_tile_the_archive_lacks_is_a_404_not_a_fetch_elsewhere(serve: Serve) -> None:
    with serve.client() as api:
        assert api.get("/tiles/19/0/0.png").status_code == 404
        config = api.get("/config").json()
    assert config["map_tiles_offline"] is True
    assert config["map_tile_url"].startswith("/api/v1/tiles/")
    assert Path(urlsplit(config["map_tile_url"]).path).suffix == ".png"
