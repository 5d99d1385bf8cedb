"""What the page asks the server before it draws: its map settings and its session."""

from __future__ import annotations

from pydantic import BaseModel, Field


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


class SessionOut(BaseModel):
    role: str
