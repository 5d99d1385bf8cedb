"""Offline map tiles from a local archive named at start: PMTiles (read with the `pmtiles`
package) or MBTiles (SQLite, read with the standard library), raster tiles only.

Tiles are addressed as the page's map asks for them: XYZ, y down from the north (MBTiles
stores TMS rows, y up from the south: flipped here). Reads block on the file, so the route
runs them in a worker thread; the SQLite connection is shared behind a lock."""

from __future__ import annotations

import gzip
import sqlite3
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from pmtiles.reader import MmapSource, Reader
from pmtiles.tile import (
    Compression,
    Entry,
    TileType,
    deserialize_directory,
    find_tile,
    zxy_to_tileid,
)

from server.settings import SettingsError

PMTILES_MAGIC = b"PMTiles"
SQLITE_MAGIC = b"SQLite format 3\x00"
# the raster formats a browser draws, by the extension the tile URL carries
MEDIA_TYPES = {"png": "image/png", "jpg": "image/jpeg", "webp": "image/webp"}
_PMTILES_FORMATS = {TileType.PNG: "png", TileType.JPEG: "jpg", TileType.WEBP: "webp"}
_MBTILES_FORMATS = {"png": "png", "jpg": "jpg", "jpeg": "jpg", "webp": "webp"}
MAX_ZOOM = 30
_DIRECTORIES_KEPT = 64  # a leaf directory holds thousands of tiles' entries


class TileArchiveError(SettingsError):
    """The file named by map_tiles is no archive of raster tiles this server can serve."""


@dataclass(frozen=True)
class TileArchiveInfo:
    kind: str  # "pmtiles" or "mbtiles"
    format: str  # "png", "jpg" or "webp": the tile URL's extension
    min_zoom: int
    max_zoom: int
    bounds: tuple[float, float, float, float] | None  # west, south, east, north (degrees)
    attribution: str

    @property
    def media_type(self) -> str:
        return MEDIA_TYPES[self.format]


class TileArchive(Protocol):
    info: TileArchiveInfo

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        """The tile's bytes as stored, or None when the archive has none there."""

    def close(self) -> None: ...


def archive_kind(path: Path) -> str:
    """'pmtiles' or 'mbtiles', by the file's first bytes (not its name)."""
    try:
        with path.open("rb") as f:
            head = f.read(len(SQLITE_MAGIC))
    except OSError as exc:
        raise TileArchiveError(f"map_tiles: cannot read {path}: {exc.strerror}") from None
    if head.startswith(PMTILES_MAGIC):
        return "pmtiles"
    if head == SQLITE_MAGIC:
        return "mbtiles"
    raise TileArchiveError(f"map_tiles: {path} is neither a PMTiles nor an MBTiles archive")


def open_tile_archive(path: Path) -> TileArchive:
    if archive_kind(path) == "pmtiles":
        return PmTilesArchive(path)
    return MbTilesArchive(path)


class PmTilesArchive:
    def __init__(self, path: Path) -> None:
        self._file = path.open("rb")
        try:
            self._reader = Reader(MmapSource(self._file))  # type: ignore[no-untyped-call]
            header = self._reader.header()  # type: ignore[no-untyped-call]
            tile_format = _PMTILES_FORMATS.get(header["tile_type"])
            if tile_format is None:
                raise TileArchiveError(
                    f"{path} holds {header['tile_type'].name} tiles, not raster images"
                )
            metadata: dict[str, Any] = self._reader.metadata()  # type: ignore[no-untyped-call]
        except (TileArchiveError, ValueError, OSError) as exc:
            self._file.close()
            if isinstance(exc, TileArchiveError):
                raise
            raise TileArchiveError(f"{path}: not a readable PMTiles archive ({exc})") from None
        self._gzipped = header["tile_compression"] == Compression.GZIP
        self._header = header
        # parsed directories by (offset, length): the root and the leaves asked for so far
        # (pmtiles' Reader.get parses the root again for every tile)
        self._directories: dict[tuple[int, int], list[Entry]] = {}
        self._lock = threading.Lock()
        bounds = tuple(header[k] / 1e7 for k in ("min_lon_e7", "min_lat_e7", "max_lon_e7",
                                                 "max_lat_e7"))  # fmt: skip
        self.info = TileArchiveInfo(
            "pmtiles", tile_format, header["min_zoom"], header["max_zoom"],
            _bounds(bounds), str(metadata.get("attribution", "")),
        )  # fmt: skip

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        header = self._header
        tile_id = zxy_to_tileid(z, x, y)
        offset, length = header["root_offset"], header["root_length"]
        for _depth in range(4):  # the spec's deepest directory tree
            entry = find_tile(self._directory(offset, length), tile_id)
            if entry is None:
                return None
            if entry.run_length > 0:
                at = header["tile_data_offset"] + entry.offset
                data = bytes(self._reader.get_bytes(at, entry.length))
                return gzip.decompress(data) if self._gzipped else data
            offset, length = header["leaf_directory_offset"] + entry.offset, entry.length
        return None

    def _directory(self, offset: int, length: int) -> list[Entry]:
        with self._lock:
            entries = self._directories.get((offset, length))
            if entries is None:
                if len(self._directories) >= _DIRECTORIES_KEPT:
                    self._directories.clear()
                entries = deserialize_directory(self._reader.get_bytes(offset, length))
                self._directories[(offset, length)] = entries
            return entries

    def close(self) -> None:
        self._file.close()


class MbTilesArchive:
    def __init__(self, path: Path) -> None:
        self._db = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True,
                                   check_same_thread=False)  # fmt: skip
        self._lock = threading.Lock()
        try:
            metadata = dict(self._db.execute("SELECT name, value FROM metadata").fetchall())
            low, high = self._db.execute(
                "SELECT MIN(zoom_level), MAX(zoom_level) FROM tiles").fetchone()  # fmt: skip
        except sqlite3.Error as exc:
            self._db.close()
            raise TileArchiveError(f"{path}: not a readable MBTiles archive ({exc})") from None
        tile_format = _MBTILES_FORMATS.get(str(metadata.get("format", "png")).lower())
        if tile_format is None:
            self._db.close()
            raise TileArchiveError(f"{path} holds {metadata['format']} tiles, not raster images")
        self.info = TileArchiveInfo(
            "mbtiles", tile_format, int(metadata.get("minzoom", low or 0)),
            int(metadata.get("maxzoom", high or 0)), _mbtiles_bounds(metadata.get("bounds")),
            str(metadata.get("attribution", "")),
        )  # fmt: skip

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        tms_row = (1 << z) - 1 - y
        with self._lock:
            row = self._db.execute(
                "SELECT tile_data FROM tiles WHERE zoom_level=? AND tile_column=? AND tile_row=?",
                (z, x, tms_row),
            ).fetchone()
        return bytes(row[0]) if row is not None else None

    def close(self) -> None:
        with self._lock:
            self._db.close()


def _bounds(values: tuple[float, ...]) -> tuple[float, float, float, float] | None:
    west, south, east, north = values
    if not (-180.0 <= west < east <= 180.0 and -90.0 <= south < north <= 90.0):
        return None
    return west, south, east, north


def _mbtiles_bounds(text: str | None) -> tuple[float, float, float, float] | None:
    try:
        values = tuple(float(v) for v in (text or "").split(","))
    except ValueError:
        return None
    return _bounds(values) if len(values) == 4 else None
