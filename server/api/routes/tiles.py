"""The offline map's tiles: GET /tiles/{z}/{x}/{y}.{ext} from the archive named by
map_tiles, behind the token (the page's cookie carries it for the map's <img> requests).

A tile's ETag is a digest of its bytes, so a browser revalidating gets 304 while the
archive holds the same tile, whatever file it comes from; Cache-Control lets the browser
keep it for a day without asking, privately (it is behind a token)."""

from __future__ import annotations

import asyncio
import hashlib
from typing import Annotated

from fastapi import APIRouter, Header, Path, Response

from server.http.deps import Context, Reader
from server.http.errors import AUTH_RESPONSES, ApiError
from server.http.routing import route
from server.http.tile_archive import MAX_ZOOM, MEDIA_TYPES
from skyhelm_wire.calls import API_PREFIX, CALL

router = APIRouter(prefix=API_PREFIX, tags=["map"])

CACHE_CONTROL = "private, max-age=86400"
_TILE_RESPONSES = {
    **AUTH_RESPONSES,
    200: {"content": {media: {} for media in MEDIA_TYPES.values()}, "description": "the tile"},
    304: {"description": "the tile the browser holds (If-None-Match) is current"},
    404: {"description": "no archive configured, or no tile there"},
}


def tile_etag(data: bytes) -> str:
    return f'"{hashlib.blake2b(data, digest_size=12).hexdigest()}"'


def _matches(if_none_match: str | None, etag: str) -> bool:
    if not if_none_match:
        return False
    tags = [t.strip().removeprefix("W/") for t in if_none_match.split(",")]
    return etag in tags or "*" in tags


@route(
    router,
    CALL["tile"],
    response_class=Response,
    responses=_TILE_RESPONSES,
    summary="A tile of the offline map's archive (map_tiles)",
)
async def tile(
    context: Context,
    _role: Reader,
    z: Annotated[int, Path(ge=0, le=MAX_ZOOM, description="zoom level")],
    x: Annotated[int, Path(ge=0, description="column, from the west")],
    y: Annotated[int, Path(ge=0, description="row, from the north (XYZ, as Leaflet)")],
    ext: Annotated[
        str,
        Path(pattern=r"^[A-Za-z0-9]+$", description="the archive's tile format: png, jpg or webp"),
    ],
    if_none_match: Annotated[str | None, Header()] = None,
) -> Response:
    archive = context.tiles
    if archive is None:
        raise ApiError(404, "no map tile archive: the server was started without map_tiles")
    if ext != archive.info.format:
        raise ApiError(404, f"the archive holds {archive.info.format} tiles", field="ext")
    if x >= 1 << z or y >= 1 << z:
        raise ApiError(404, f"no tile {x}/{y} at zoom {z}: both must be below {1 << z}")
    data = await asyncio.to_thread(archive.tile, z, x, y)
    if data is None:
        raise ApiError(404, f"the archive has no tile {z}/{x}/{y}")
    etag = tile_etag(data)
    headers = {"ETag": etag, "Cache-Control": CACHE_CONTROL}
    if _matches(if_none_match, etag):
        return Response(status_code=304, headers=headers)
    return Response(data, media_type=archive.info.media_type, headers=headers)
