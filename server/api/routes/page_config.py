"""What the page needs to know of the server's settings: the 2D map's tiles, whether it is a
fleet server and whether it serves the 3D scene. Behind the token, since a tile URL may carry
the tile provider's key."""

from __future__ import annotations

from fastapi import APIRouter

from server.http.deps import Context, Reader
from server.http.errors import AUTH_RESPONSES
from server.http.routing import route
from skyhelm_wire.calls import API_PREFIX, CALL
from skyhelm_wire.page import PageConfigOut

router = APIRouter(prefix=API_PREFIX, tags=["health"])


def archive_tile_url(tile_format: str) -> str:
    """Leaflet's template of the offline archive's tiles, as the tiles route serves them
    (the page's own origin): /api/v1/tiles/{z}/{x}/{y}.png"""
    return API_PREFIX + CALL["tile"].route.replace("{ext}", tile_format)


@route(router, CALL["page_config"], responses=AUTH_RESPONSES)
async def page_config(context: Context, _role: Reader) -> PageConfigOut:
    settings = context.settings
    archive = context.tiles
    if archive is None:
        return PageConfigOut(
            map_tile_url=settings.map_tile_url,
            map_tile_attribution=settings.map_tile_attribution,
            fleet=settings.fleet,
            scene=settings.scene,
        )
    info = archive.info
    return PageConfigOut(
        map_tile_url=archive_tile_url(info.format),
        map_tile_attribution=settings.map_tile_attribution or info.attribution,
        map_tiles_offline=True,
        map_tile_min_zoom=info.min_zoom,
        map_tile_max_zoom=info.max_zoom,
        map_tile_bounds=list(info.bounds) if info.bounds else None,
        fleet=settings.fleet,
        scene=settings.scene,
    )
