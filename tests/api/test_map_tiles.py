"""Offline map tiles: the server serves a PMTiles or MBTiles archive named at start behind
the token, with ETag/Cache-Control and 304, 404 where it has no tile; the page's config
points the map at it. The archives are made here from generated tiles; no network."""

from __future__ import annotations

import contextlib
import http.server
import io
import socket
import subprocess
import sys
import threading
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import httpx
import pytest

from server.http.tile_archive import open_tile_archive
from server.map_tiles import ArchiveInfo, Progress, Tile, fetch_tiles, tiles_in, write_archive
from server.settings import SettingsError
from tests.api.conftest import OBSERVER, Api, api_for, auth
from tests.map_tiles import make_archive, solid_png, tile_colour

NO_VEHICLE = ["udpin:127.0.0.1:0"]


@contextlib.asynccontextmanager
async def _serving(archive: Path) -> AsyncIterator[Api]:
    async with api_for(None, connect=NO_VEHICLE, map_tiles=archive) as api:
        yield api


@pytest.mark.parametrize("suffix", [".pmtiles", ".mbtiles"])
async def test_tiles_come_from_the_archive_with_caching_headers(
    tmp_path: Path, suffix: str
) -> None:
    archive = tmp_path / f"field{suffix}"
    tiles = make_archive(archive)
    z, x, y, data = tiles[len(tiles) // 2]
    other = next(t for t in tiles if t[3] != data)
    async with _serving(archive) as api:
        url = f"/api/v1/tiles/{z}/{x}/{y}.png"
        answer = await api.client.get(url, headers=auth(OBSERVER))
        assert answer.status_code == 200, answer.text
        assert answer.content == data
        assert answer.headers["content-type"] == "image/png"
        assert "max-age=" in answer.headers["cache-control"]
        assert "private" in answer.headers["cache-control"]
        etag = answer.headers["etag"]
        # the browser's copy is current: 304, no body
        again = await api.client.get(url, headers={"If-None-Match": etag})
        assert again.status_code == 304
        assert again.content == b""
        assert again.headers["etag"] == etag
        # another tile, another tag
        second = await api.client.get(f"/api/v1/tiles/{other[0]}/{other[1]}/{other[2]}.png")
        assert second.headers["etag"] != etag
        stale = await api.client.get(url, headers={"If-None-Match": second.headers["etag"]})
        assert stale.status_code == 200
        assert stale.content == data


async def test_missing_tiles_are_404_and_tiles_need_the_token(tmp_path: Path) -> None:
    archive = tmp_path / "field.pmtiles"
    z, x, y, _ = make_archive(archive)[0]
    async with _serving(archive) as api:
        client = api.client
        assert (await client.get(f"/api/v1/tiles/{z}/0/0.png")).status_code == 404
        assert (await client.get(f"/api/v1/tiles/2/{x}/{y}.png")).status_code == 404  # x ≥ 4
        assert (await client.get(f"/api/v1/tiles/{z}/{x}/{y}.jpg")).status_code == 404
        assert (await client.get(f"/api/v1/tiles/99/{x}/{y}.png")).status_code == 422
        async with httpx.AsyncClient(
            transport=httpx.ASGITransport(app=api.app), base_url="http://testserver"
        ) as anonymous:
            assert (await anonymous.get(f"/api/v1/tiles/{z}/{x}/{y}.png")).status_code == 401


async def test_the_page_config_points_the_map_at_the_archive(tmp_path: Path) -> None:
    archive = tmp_path / "field.mbtiles"
    make_archive(archive, zooms=range(15, 19), attribution="© Field survey")
    async with _serving(archive) as api:
        config = (await api.client.get("/api/v1/config")).json()
    assert config["map_tile_url"] == "/api/v1/tiles/{z}/{x}/{y}.png"
    assert config["map_tiles_offline"] is True
    assert (config["map_tile_min_zoom"], config["map_tile_max_zoom"]) == (15, 18)
    assert config["map_tile_attribution"] == "© Field survey"
    west, south, east, north = config["map_tile_bounds"]
    assert west < 8.545594 < east
    assert south < 47.397742 < north


async def test_without_an_archive_tiles_are_404() -> None:
    async with api_for(None, connect=NO_VEHICLE) as api:
        answer = await api.client.get("/api/v1/tiles/1/0/0.png")
    assert answer.status_code == 404
    assert "map_tiles" in answer.json()["detail"]["reason"]


def test_a_file_that_is_no_archive_is_refused_at_start(tmp_path: Path) -> None:
    from server.app import create_app
    from tests.api.conftest import make_settings

    not_tiles = tmp_path / "notes.pmtiles"
    not_tiles.write_text("hello")
    with pytest.raises(SettingsError, match="neither a PMTiles nor an MBTiles"):
        create_app(make_settings(None, map_tiles=not_tiles))
    with pytest.raises(SettingsError, match="cannot read"):
        create_app(make_settings(None, map_tiles=tmp_path / "absent.mbtiles"))
    with pytest.raises(SettingsError, match="give one"):
        make_settings(None, map_tiles=not_tiles, map_tile_url="https://t.example/{z}/{x}/{y}.png")


def test_make_tiles_fetches_a_box_into_an_archive_the_server_reads(tmp_path: Path) -> None:
    """The online tool, against a tile server this test plays (httpx's mock transport)."""
    asked: list[str] = []

    def tile_server(request: httpx.Request) -> httpx.Response:
        asked.append(request.url.path)
        z, x, y = (int(p) for p in request.url.path.removesuffix(".png").split("/")[-3:])
        if (x + y) % 3 == 0:
            return httpx.Response(404)  # a tile the server lacks
        return httpx.Response(200, content=solid_png(tile_colour(z, x, y), size=8))

    bounds = (8.54, 47.395, 8.55, 47.40)
    coords = tiles_in(bounds, range(15, 17))
    with httpx.Client(transport=httpx.MockTransport(tile_server)) as client:
        tiles: list[Tile] = list(fetch_tiles(client, "https://t.example/{z}/{x}/{y}.png", coords))
    assert len(asked) == len(coords)
    assert 0 < len(tiles) < len(coords)
    for suffix in (".pmtiles", ".mbtiles"):
        path = tmp_path / f"area{suffix}"
        write_archive(path, tiles, ArchiveInfo(bounds, "© Example"))
        archive = open_tile_archive(path)
        try:
            assert all(archive.tile(z, x, y) == data for z, x, y, data in tiles)
            assert archive.info.min_zoom == 15
            assert archive.info.max_zoom == 16
        finally:
            archive.close()


# -- `skyhelm tiles`: the command, run as a user runs it (any directory, no network) ----------

SKYHELM = Path(sys.executable).with_name("skyhelm")
SMALL_BOX = "8.544,47.397,8.547,47.399"


def _closed_port() -> int:
    """A loopback port nobody listens on (bound, then let go)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def _tiles_command(cwd: Path, url: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(SKYHELM), "tiles", "--url", url, "--bbox", SMALL_BOX, "--pause", "0", *args],
        cwd=cwd, capture_output=True, text=True, timeout=60,
    )  # fmt: skip


def test_tiles_without_network_is_one_clear_line_and_no_traceback(tmp_path: Path) -> None:
    url = f"http://127.0.0.1:{_closed_port()}/{{z}}/{{x}}/{{y}}.png"
    done = _tiles_command(tmp_path, url, "--zoom", "16", "--out", "field.pmtiles")
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("skyhelm tiles: cannot reach http://127.0.0.1:"), done.stderr
    assert "no network?" in last
    assert not (tmp_path / "field.pmtiles").exists()


class _TileHandler(http.server.BaseHTTPRequestHandler):
    def do_GET(self) -> None:
        z, x, y = (int(p) for p in self.path.removesuffix(".png").split("/")[-3:])
        body = solid_png(tile_colour(z, x, y), size=8)
        self.send_response(200)
        self.send_header("Content-Type", "image/png")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: object) -> None:
        pass


@contextlib.contextmanager
def _tile_server() -> Iterator[str]:
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _TileHandler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/{{z}}/{{x}}/{{y}}.png"
    finally:
        server.shutdown()
        server.server_close()


def test_tiles_from_any_directory_shows_progress_and_writes_the_archive(tmp_path: Path) -> None:
    coords = tiles_in((8.544, 47.397, 8.547, 47.399), range(16, 19))
    with _tile_server() as url:
        done = _tiles_command(tmp_path, url, "--zoom", "16-18", "--out", "area.mbtiles")
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert lines[0].startswith(f"fetching {len(coords)} tiles")
    bars = [line for line in lines if line.startswith("[")]
    # not a terminal: a line at each tenth, the last one full
    assert 2 <= len(bars) <= 11
    full = "#" * Progress.width
    assert bars[-1].startswith(f"[{full}] {len(coords)}/{len(coords)} tiles 100%")
    assert lines[-1].startswith("area.mbtiles: ")
    archive = open_tile_archive(tmp_path / "area.mbtiles")  # written where it was run
    try:
        z, x, y = coords[0]
        assert archive.tile(z, x, y) == solid_png(tile_colour(z, x, y), size=8)
    finally:
        archive.close()


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_on_a_terminal_is_one_bar_redrawn_in_place() -> None:
    out = _Terminal()
    progress = Progress(4, out, clock=lambda: 0.0)
    for _ in range(4):
        progress.advance()
    progress.end_line()
    text = out.getvalue()
    assert text.count("\r") == 4
    assert text.count("\n") == 1
    assert text.rstrip("\n").split("\r")[-1] == "[" + "#" * Progress.width + "] 4/4 tiles 100% 0 s"
    assert "2/4 tiles  50%" in text
