"""What the page needs to know of the server's settings: the 2D map's tiles, whether it is a
fleet server and whether it serves the 3D scene. Behind the token, since a tile URL may carry
the tile provider's key."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, Field

from server.http.deps import Context, Reader
from server.http.errors import AUTH_RESPONSES

router = APIRouter(tags=["health"])
# the offline archive's tiles, as the tiles route serves them (the page's own origin)
ARCHIVE_TILE_URL = "/api/v1/tiles/{{z}}/{{x}}/{{y}}.{format}"


class PageConfigOut(BaseModel):
    map_tile_url: str | None = Field(
        description="Leaflet tile template ({z}/{x}/{y}); null: the map draws a metre grid"
    )
    map_tile_attribution: str
    map_tiles_offline: bool = Field(
        default=False, description="the tiles come from this server's archive (map_tiles)"
    )
    map_tile_min_zoom: int | None = Field(
        default=None, description="the archive's lowest zoom level"
    )
    map_tile_max_zoom: int | None = Field(
        default=None, description="the archive's highest zoom level: beyond, tiles are scaled"
    )
    map_tile_bounds: list[float] | None = Field(
        default=None, description="west, south, east, north (degrees) the archive covers"
    )
    fleet: bool = Field(description="a fleet server (--fleet): /api/v1/fleet and its socket")
    scene: bool = Field(
        default=True, description="the 3D scene is served at /scene/ (false: --no-scene)"
    )


@router.get("/config", response_model=PageConfigOut, responses=AUTH_RESPONSES)
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
        map_tile_url=ARCHIVE_TILE_URL.format(format=info.format),
        map_tile_attribution=settings.map_tile_attribution or info.attribution,
        map_tiles_offline=True,
        map_tile_min_zoom=info.min_zoom,
        map_tile_max_zoom=info.max_zoom,
        map_tile_bounds=list(info.bounds) if info.bounds else None,
        fleet=settings.fleet,
        scene=settings.scene,
    )
