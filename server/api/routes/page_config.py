"""What the page needs to know of the server's settings: the 2D map's tiles, and whether
it is a fleet server. Behind the token, since a tile URL may carry the tile provider's key."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, Field

from server.http.deps import Context, Reader
from server.http.errors import AUTH_RESPONSES

router = APIRouter(tags=["health"])


class PageConfigOut(BaseModel):
    map_tile_url: str | None = Field(
        description="Leaflet tile template ({z}/{x}/{y}); null: the map draws a metre grid"
    )
    map_tile_attribution: str
    fleet: bool = Field(description="a fleet server (--fleet): /api/v1/fleet and its socket")


@router.get("/config", response_model=PageConfigOut, responses=AUTH_RESPONSES)
async def page_config(context: Context, _role: Reader) -> PageConfigOut:
    settings = context.settings
    return PageConfigOut(
        map_tile_url=settings.map_tile_url,
        map_tile_attribution=settings.map_tile_attribution,
        fleet=settings.fleet,
    )
