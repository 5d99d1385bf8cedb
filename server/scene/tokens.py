"""Where the scene looks for the API token: query, cookie, or Authorization header."""

from __future__ import annotations

from collections.abc import Mapping

TOKEN_COOKIE = "skyhelm_token"


def token_from_request(
    query: Mapping[str, str], cookies: Mapping[str, str], headers: Mapping[str, str]
) -> str | None:
    """The token a request carries; the viser client's WebSocket can only carry the cookie,
    because the client derives its socket URL from the page URL without the query string."""
    token = query.get("token")
    if token:
        return token
    token = cookies.get(TOKEN_COOKIE)
    if token:
        return token
    auth = headers.get("authorization", "")
    scheme, _, value = auth.partition(" ")
    if scheme.lower() == "bearer" and value.strip():
        return value.strip()
    return None


def origin_matches_host(headers: Mapping[str, str]) -> bool:
    """Browsers always send Origin on WebSockets; a page from elsewhere must not ride the cookie."""
    origin = headers.get("origin")
    if origin is None:
        return True
    host = headers.get("host", "")
    return origin.split("://", 1)[-1].rstrip("/") == host
