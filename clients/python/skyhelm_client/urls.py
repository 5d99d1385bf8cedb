"""Where the server is: the URL ``skyhelm serve`` prints, and its sockets' (each socket's
path is the wire's, ``skyhelm_wire.sockets``)."""

from __future__ import annotations

from urllib.parse import parse_qs, urlencode, urlsplit

from skyhelm_wire.calls import API_PREFIX
from skyhelm_wire.sockets import SOCKET

__all__ = ["API_PREFIX", "socket_url", "split_url", "ws_url"]


def split_url(url: str, token: str | None) -> tuple[str, str]:
    """``http://host:port/?token=T`` (what ``skyhelm serve`` prints) or a base URL and a
    token: the base URL and the token."""
    parts = urlsplit(url)
    if parts.scheme not in ("http", "https") or not parts.netloc:
        raise ValueError(f"not an http(s) URL: {url!r}")
    found = parse_qs(parts.query).get("token")
    token = token or (found[0] if found else None)
    if not token:
        raise ValueError("no token: pass token= or the URL with ?token=")
    return f"{parts.scheme}://{parts.netloc}", token


def socket_url(base_url: str, name: str, query: dict[str, object]) -> str:
    """The URL of the socket ``name`` of the wire's table (``SOCKET``) with ``query``: ws://
    for an http:// server, wss:// for https://."""
    scheme = "wss" if base_url.startswith("https") else "ws"
    path = SOCKET[name].url_path
    return f"{scheme}://{base_url.split('://', 1)[1]}{path}?{urlencode(query)}"


def ws_url(base_url: str, token: str, vehicle: int | None, rate_hz: float) -> str:
    """The telemetry socket's URL: one vehicle's (or every vehicle's) at ``rate_hz``."""
    query: dict[str, object] = {"rate_hz": rate_hz, "token": token}
    if vehicle is not None:
        query["vehicle"] = vehicle
    return socket_url(base_url, "telemetry", query)
