"""The 2D map's tile setting: one URL template, also the one host the page's CSP lets
images come from (``tile_origin``)."""

from __future__ import annotations

from urllib.parse import urlsplit

_PLACEHOLDERS = ("{z}", "{x}", "{y}")


def check_tile_url(url: str) -> str:
    """A Leaflet tile template: http(s), a host, and the {z}/{x}/{y} placeholders."""
    parts = urlsplit(url.replace("{s}", "a"))
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError("map_tile_url must be an http(s) URL with a host")
    missing = [p for p in _PLACEHOLDERS if p not in url]
    if missing:
        raise ValueError(f"map_tile_url lacks {', '.join(missing)}")
    return url


def tile_origin(url: str | None) -> str | None:
    """The origin tiles come from, for the CSP's img-src ("https://*.tile.example.org" when
    the template spreads over {s} subdomains); None without tiles."""
    if url is None:
        return None
    parts = urlsplit(url.replace("{s}", "a"))
    host = parts.netloc
    if "{s}" in url:
        host = "*." + host.split(".", 1)[1] if "." in host else host
    return f"{parts.scheme}://{host}"
