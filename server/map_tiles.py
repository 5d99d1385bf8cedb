"""`skyhelm tiles`: make an offline map archive for a flying area while online: fetch the
raster tiles of a box over a range of zoom levels from an XYZ tile server and write them into
one PMTiles or MBTiles file, which `skyhelm serve --map-tiles FILE` then serves with no
network (copy the file to the laptop that flies)::

    skyhelm tiles --url 'https://tiles.example.com/{z}/{x}/{y}.png' \\
        --bbox 8.535,47.392,8.556,47.403 --zoom 14-19 --attribution '© Example' \\
        --out field.pmtiles            # or field.mbtiles

Use a tile server whose terms allow downloading for offline use (your own, or a provider
that permits it): the public OpenStreetMap tile servers forbid bulk downloads. The command
asks one tile at a time, says who it is (--user-agent), refuses more than --max-tiles, shows
its progress on stderr and, when the server cannot be reached, says so in one line (exit 1).
"""

from __future__ import annotations

import argparse
import math
import sqlite3
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from pmtiles.tile import Compression, TileType, zxy_to_tileid
from pmtiles.writer import Writer

Tile = tuple[int, int, int, bytes]  # z, x, y (XYZ: y from the north), image bytes
Bounds = tuple[float, float, float, float]  # west, south, east, north (degrees)
MAX_MERCATOR_LAT = 85.0511287798066
DEFAULT_MAX_TILES = 20000
USER_AGENT = "SkyHelm-make-tiles (offline map for a flying area)"

if TYPE_CHECKING:
    # imported where a fetch needs it: `skyhelm serve` and every other command build this
    # command's parser (`import server.cli`, 10 runs: 15.6 CPU-s with httpx, 14.7 without)
    import httpx

_PMTILES_TYPES = {"png": TileType.PNG, "jpg": TileType.JPEG, "webp": TileType.WEBP}


def image_format(data: bytes) -> str:
    """png, jpg or webp, by the image's first bytes."""
    if data.startswith(b"\x89PNG\r\n\x1a\n"):
        return "png"
    if data.startswith(b"\xff\xd8\xff"):
        return "jpg"
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "webp"
    raise ValueError("a tile is not a PNG, JPEG or WebP image")


def tile_xy(lon_deg: float, lat_deg: float, z: int) -> tuple[int, int]:
    """The XYZ tile (Web Mercator) holding a point at zoom z."""
    n = 1 << z
    lat = math.radians(max(-MAX_MERCATOR_LAT, min(MAX_MERCATOR_LAT, lat_deg)))
    x = int((lon_deg + 180.0) / 360.0 * n)
    y = int((1.0 - math.asinh(math.tan(lat)) / math.pi) / 2.0 * n)
    return min(max(x, 0), n - 1), min(max(y, 0), n - 1)


def tiles_in(bounds: Bounds, zooms: Iterable[int]) -> list[tuple[int, int, int]]:
    """Every (z, x, y) covering the box at each zoom."""
    west, south, east, north = bounds
    found = []
    for z in zooms:
        x0, y0 = tile_xy(west, north, z)
        x1, y1 = tile_xy(east, south, z)
        found += [(z, x, y) for x in range(x0, x1 + 1) for y in range(y0, y1 + 1)]
    return found


@dataclass(frozen=True)
class ArchiveInfo:
    bounds: Bounds
    attribution: str = ""
    name: str = "SkyHelm offline map"


def write_archive(path: Path, tiles: Sequence[Tile], info: ArchiveInfo) -> None:
    """Writes the tiles as PMTiles (*.pmtiles) or MBTiles (*.mbtiles), replacing the file."""
    if not tiles:
        raise ValueError("no tiles to write")
    formats = {image_format(data) for *_, data in tiles}
    if len(formats) != 1:
        raise ValueError(f"tiles of several formats: {sorted(formats)}")
    tile_format = formats.pop()
    if path.suffix == ".pmtiles":
        _write_pmtiles(path, tiles, tile_format, info)
    elif path.suffix == ".mbtiles":
        _write_mbtiles(path, tiles, tile_format, info)
    else:
        raise ValueError(f"{path}: name it *.pmtiles or *.mbtiles")


def _write_pmtiles(path: Path, tiles: Sequence[Tile], tile_format: str, info: ArchiveInfo) -> None:
    west, south, east, north = info.bounds
    zooms = [z for z, *_ in tiles]
    header = {
        "tile_type": _PMTILES_TYPES[tile_format], "tile_compression": Compression.NONE,
        "min_lon_e7": round(west * 1e7), "min_lat_e7": round(south * 1e7),
        "max_lon_e7": round(east * 1e7), "max_lat_e7": round(north * 1e7),
        "center_zoom": (min(zooms) + max(zooms)) // 2,
        "center_lon_e7": round((west + east) / 2 * 1e7),
        "center_lat_e7": round((south + north) / 2 * 1e7),
    }  # fmt: skip
    metadata = {"name": info.name, "attribution": info.attribution, "format": tile_format}
    ordered = sorted(tiles, key=lambda t: zxy_to_tileid(t[0], t[1], t[2]))
    with path.open("wb") as f:
        writer = Writer(f)  # type: ignore[no-untyped-call]
        for z, x, y, data in ordered:
            writer.write_tile(zxy_to_tileid(z, x, y), data)  # type: ignore[no-untyped-call]
        writer.finalize(header, metadata)  # type: ignore[no-untyped-call]


def _write_mbtiles(path: Path, tiles: Sequence[Tile], tile_format: str, info: ArchiveInfo) -> None:
    path.unlink(missing_ok=True)
    zooms = [z for z, *_ in tiles]
    metadata = {
        "name": info.name, "format": tile_format, "type": "baselayer", "version": "1",
        "attribution": info.attribution, "bounds": ",".join(f"{v:.7f}" for v in info.bounds),
        "minzoom": str(min(zooms)), "maxzoom": str(max(zooms)),
    }  # fmt: skip
    db = sqlite3.connect(path)
    try:
        with db:
            db.execute("CREATE TABLE metadata (name TEXT, value TEXT)")
            db.execute("CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, "
                       "tile_row INTEGER, tile_data BLOB)")  # fmt: skip
            db.execute(
                "CREATE UNIQUE INDEX tile_index ON tiles (zoom_level, tile_column, tile_row)"
            )
            db.executemany("INSERT INTO metadata VALUES (?, ?)", metadata.items())
            # MBTiles rows are TMS: counted from the south
            db.executemany("INSERT INTO tiles VALUES (?, ?, ?, ?)",
                           [(z, x, (1 << z) - 1 - y, data) for z, x, y, data in tiles])  # fmt: skip
    finally:
        db.close()


def fetch_tiles(
    client: httpx.Client,
    url: str,
    coords: Sequence[tuple[int, int, int]],
    pause_s: float = 0.0,
    asked: Callable[[], None] | None = None,
) -> Iterator[Tile]:
    """Each tile from the XYZ server ({z}/{x}/{y}, {s} as "a"); a 404 is a tile the
    server lacks and is skipped, any other failure stops. ``asked`` is called after each
    answer (the progress)."""
    import httpx

    for z, x, y in coords:
        answer = client.get(url.replace("{s}", "a").format(z=z, x=x, y=y))
        if asked is not None:
            asked()
        if answer.status_code == httpx.codes.NOT_FOUND:
            continue
        answer.raise_for_status()
        yield z, x, y, answer.content
        if pause_s:
            time.sleep(pause_s)


class Progress:
    """How far the fetch is: one bar redrawn in place on a terminal; on a pipe or a file
    (a log), a line at each tenth, so the log stays short."""

    width = 30

    def __init__(
        self, total: int, out: TextIO, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.total = max(total, 1)
        self.done = 0
        self.out = out
        self.terminal = out.isatty()
        self._clock = clock
        self._start_s = clock()
        self._tenth = -1
        self._open = False  # a bar drawn without its newline

    def line(self) -> str:
        filled = self.done * self.width // self.total
        percent = self.done * 100 // self.total
        elapsed_s = self._clock() - self._start_s
        bar = "#" * filled + "." * (self.width - filled)
        return f"[{bar}] {self.done}/{self.total} tiles {percent:3d}% {elapsed_s:.0f} s"

    def advance(self) -> None:
        self.done += 1
        if self.terminal:
            self.out.write("\r" + self.line())
            self._open = True
        elif (tenth := self.done * 10 // self.total) != self._tenth:
            self._tenth = tenth
            self.out.write(self.line() + "\n")
        self.out.flush()

    def end_line(self) -> None:
        """Ends the bar's line, so what is written next starts on its own."""
        if self._open:
            self.out.write("\n")
            self._open = False


def _bbox(text: str) -> Bounds:
    values = tuple(float(v) for v in text.split(","))
    if len(values) != 4:
        raise argparse.ArgumentTypeError("west,south,east,north")
    west, south, east, north = values
    if not (-180 <= west < east <= 180 and -90 <= south < north <= 90):
        raise argparse.ArgumentTypeError("west < east and south < north, in degrees")
    return west, south, east, north


def _zooms(text: str) -> range:
    low, _, high = text.partition("-")
    first, last = int(low), int(high or low)
    if not 0 <= first <= last <= 22:
        raise argparse.ArgumentTypeError("a zoom level or a range like 14-19, within 0-22")
    return range(first, last + 1)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of `skyhelm tiles`."""
    parser.add_argument("--url", required=True, help="XYZ tile template: {z}/{x}/{y}")
    parser.add_argument("--bbox", type=_bbox, required=True, help="west,south,east,north")
    parser.add_argument("--zoom", type=_zooms, required=True, help="e.g. 14-19")
    parser.add_argument("--out", type=Path, required=True, help="*.pmtiles or *.mbtiles")
    parser.add_argument("--attribution", default="", help="shown on the map")
    parser.add_argument("--max-tiles", type=int, default=DEFAULT_MAX_TILES)
    parser.add_argument("--pause", type=float, default=0.05, help="seconds between tiles")
    parser.add_argument("--user-agent", default=USER_AGENT)


def _fetch_failure(exc: httpx.HTTPError) -> str:
    """One line for a fetch that failed: where, and what to do."""
    import httpx

    try:
        where = str(exc.request.url.copy_with(query=None))
    except RuntimeError:  # no request attached
        where = "the tile server"
    if isinstance(exc, httpx.HTTPStatusError):
        return f"{where} answered HTTP {exc.response.status_code}: check --url"
    reason = str(exc) or type(exc).__name__
    return (
        f"cannot reach {where} ({reason}): no network? Make the archive on a machine that is "
        "online and copy it over (README, Offline map)"
    )


def run(args: argparse.Namespace, err: TextIO | None = None) -> int:
    """`skyhelm tiles`: 0 with the archive written; 1 with one line saying why not."""
    import httpx

    err = err or sys.stderr
    coords = tiles_in(args.bbox, args.zoom)
    if len(coords) > args.max_tiles:
        print(f"skyhelm tiles: {len(coords)} tiles is more than --max-tiles {args.max_tiles}: "
              "a smaller box or fewer zoom levels", file=err)  # fmt: skip
        return 2
    print(f"fetching {len(coords)} tiles from {args.url}", file=err)
    progress = Progress(len(coords), err)
    headers = {"User-Agent": args.user_agent}
    try:
        with httpx.Client(headers=headers, timeout=30.0, follow_redirects=True) as client:
            tiles = list(fetch_tiles(client, args.url, coords, args.pause, progress.advance))
        write_archive(args.out, tiles, ArchiveInfo(args.bbox, args.attribution))
    except httpx.HTTPError as exc:
        progress.end_line()
        print(f"skyhelm tiles: {_fetch_failure(exc)}", file=err)
        return 1
    except (OSError, ValueError) as exc:
        progress.end_line()
        print(f"skyhelm tiles: cannot write {args.out}: {exc}", file=err)
        return 1
    except KeyboardInterrupt:
        progress.end_line()
        print("skyhelm tiles: interrupted, nothing written", file=err)
        return 130
    progress.end_line()
    print(f"{args.out}: {len(tiles)} tiles, zoom {args.zoom.start}-{args.zoom.stop - 1}; "
          f"serve it with: skyhelm serve --map-tiles {args.out}", file=err)  # fmt: skip
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="skyhelm tiles", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
