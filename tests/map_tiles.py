"""Small offline map archives the tests make themselves: generated PNG tiles (a colour per
tile, so each tile is told apart) around a point, written by server.map_tiles (`skyhelm tiles`)."""

from __future__ import annotations

import math
import struct
import zlib
from pathlib import Path

from server.map_tiles import ArchiveInfo, Tile, tile_xy, write_archive

# the simulated vehicle's home (PX4's SIH origin)
HOME_LAT_DEG, HOME_LON_DEG = 47.397742, 8.545594


def solid_png(rgb: tuple[int, int, int], size: int = 256) -> bytes:
    """A one-colour RGB PNG."""
    row = b"\x00" + bytes(rgb) * size  # filter byte 0, then the pixels

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    header = struct.pack(">IIBBBBB", size, size, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
            + chunk(b"IDAT", zlib.compress(row * size)) + chunk(b"IEND", b""))  # fmt: skip


def tile_colour(z: int, x: int, y: int) -> tuple[int, int, int]:
    return (z * 11) % 256, (x * 37) % 256, (y * 53) % 256


def tiles_around(
    lat_deg: float, lon_deg: float, zooms: range, reach: int, tile_px: int = 64
) -> list[Tile]:
    """The tiles within `reach` tiles of a point at each zoom, each its own colour."""
    tiles = []
    for z in zooms:
        cx, cy = tile_xy(lon_deg, lat_deg, z)
        for x in range(cx - reach, cx + reach + 1):
            for y in range(cy - reach, cy + reach + 1):
                tiles.append((z, x, y, solid_png(tile_colour(z, x, y), size=tile_px)))
    return tiles


def make_archive(
    path: Path,
    zooms: range = range(16, 19),
    reach: int = 4,
    attribution: str = "Test map",
    tile_px: int = 64,
) -> list[Tile]:
    """An archive around the simulated vehicle's home; returns its tiles."""
    tiles = tiles_around(HOME_LAT_DEG, HOME_LON_DEG, zooms, reach, tile_px)
    write_archive(path, tiles, ArchiveInfo(_covered(tiles), attribution))
    return tiles


def _covered(tiles: list[Tile]) -> tuple[float, float, float, float]:
    """West, south, east, north of the tiles of the highest zoom (all of it is there)."""
    top = max(z for z, *_ in tiles)
    xs = [x for z, x, _, _ in tiles if z == top]
    ys = [y for z, _, y, _ in tiles if z == top]
    n = 1 << top

    def lat(y: int) -> float:
        return math.degrees(math.atan(math.sinh(math.pi * (1 - 2 * y / n))))

    return min(xs) / n * 360 - 180, lat(max(ys) + 1), (max(xs) + 1) / n * 360 - 180, lat(min(ys))
