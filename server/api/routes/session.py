"""The browser session: the page trades the token it was opened with (sent as a Bearer
header) for an HttpOnly, SameSite=Strict cookie, which its WebSockets and the 3D scene under
/scene/ carry from then on, so the token leaves the URL (docs/api.md, "Security")."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response

from server.control.auth import TOKEN_COOKIE, token_from
from server.http.deps import Reader
from server.http.errors import AUTH_RESPONSES
from server.http.routing import route
from skyhelm_wire.calls import API_PREFIX, CALL
from skyhelm_wire.page import SessionOut

router = APIRouter(prefix=API_PREFIX, tags=["session"])


@route(router, CALL["open_session"], responses=AUTH_RESPONSES)
async def open_session(request: Request, response: Response, role: Reader) -> SessionOut:
    """Set the session cookie to the token this call carries (HttpOnly, SameSite=Strict,
    Secure over https); the page's sockets and the scene then need no token in their URL."""
    token = token_from(request.headers, request.query_params, request.cookies)
    assert token is not None  # Reader passed
    response.set_cookie(
        TOKEN_COOKIE,
        token,
        path="/",
        httponly=True,
        samesite="strict",
        secure=request.url.scheme == "https",
    )
    return SessionOut(role=role.value)


@route(router, CALL["close_session"], status_code=204, responses=AUTH_RESPONSES)
async def close_session(_: Reader) -> Response:
    """Forget the session cookie."""
    response = Response(status_code=204)
    response.delete_cookie(TOKEN_COOKIE, path="/", httponly=True, samesite="strict")
    return response
