"""The published contract held to the server: what FastAPI would answer otherwise than
/openapi.json says, and what the document cannot know without the server's settings.

- A control call's body and query are checked before its lease: FastAPI runs a route's
  dependencies (token, vehicle, lease) before it validates the body, so a body the schema
  forbids would be answered 423 without a lease and 422 with one. The lease dependency
  (``deps.hold_lease``) answers a refused lease only for an input the schema allows
  (``input_first``).
- A body that cannot be decoded (not UTF-8) is a 422 like any other body that is not JSON,
  not Starlette's undocumented 400.
- A documented path asked with another method is a 405 naming in ``Allow`` the methods the
  document lists there (Starlette names one route's, or the page's static files answer 404
  or a 405 with their GET and HEAD).
- The lease's TTL bounds are the server's settings: the document carries them as the
  ``ttl_s`` fields' minimum and maximum.
"""

from __future__ import annotations

import email.message
import json
import re
from typing import Any

from fastapi import FastAPI, Request
from fastapi.dependencies.utils import request_body_to_args, request_params_to_args
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import JSONResponse, Response

from server.http.errors import validation_detail
from server.http.schemas import UnprocessableOut
from server.settings import Settings

# what FastAPI answers a JSON body it could not decode
_UNDECODABLE = "There was an error parsing the body"
# the bodies whose ttl_s the lease's bounds apply to
_TTL_BODIES = ("ControlBody", "RenewBody")


def hold_to_contract(app: FastAPI, settings: Settings) -> None:
    """Install the answers and the document's bounds above on ``app``."""
    app.add_exception_handler(StarletteHTTPException, _http_error)
    plain_openapi = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = _with_ttl_bounds(plain_openapi(), settings)
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]


# -- input before the lease ---------------------------------------------------------------


async def input_first(request: Request) -> None:
    """RequestValidationError when the request's path, query or body breaks its route's
    schema; called by a dependency that is about to refuse it for another reason, once
    FastAPI has read the body (the same ``request`` holds it)."""
    route = request.scope.get("route")
    if not isinstance(route, APIRoute):
        return
    dependant = route.dependant
    errors: list[Any] = []
    errors += request_params_to_args(dependant.path_params, request.path_params)[1]
    errors += request_params_to_args(dependant.query_params, request.query_params)[1]
    if dependant.body_params:
        body = await _received_body(request)
        embed = bool(getattr(route, "_embed_body_fields", False))
        errors += (await request_body_to_args(dependant.body_params, body, embed))[1]
    if errors:
        raise RequestValidationError(errors)


async def _received_body(request: Request) -> Any:
    """The body as FastAPI hands it to validation: parsed JSON, or the bytes of another
    content type, or None when there is none (it decoded the JSON before the lease)."""
    raw = await request.body()
    if not raw:
        return None
    content_type = request.headers.get("content-type")
    if content_type:
        message = email.message.Message()
        message["content-type"] = content_type
        subtype = message.get_content_subtype()
        is_json = message.get_content_maintype() == "application" and (
            subtype == "json" or subtype.endswith("+json")
        )
        if not is_json:
            return raw
    return json.loads(raw)


# -- 400 and 405 --------------------------------------------------------------------------


async def _http_error(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, StarletteHTTPException)
    if exc.status_code == 400 and exc.detail == _UNDECODABLE:
        detail = [{"type": "json_invalid", "loc": ["body"], "msg": "the body is not JSON",
                   "input": {}}]  # fmt: skip
        return JSONResponse(UnprocessableOut(detail=validation_detail(detail)).model_dump(),
                            status_code=422)  # fmt: skip
    if exc.status_code in (404, 405):
        # a documented path asked with a method it does not offer (the page's static files
        # answer 404 or 405 for every path no route takes)
        allowed = _allowed_methods(request)
        if allowed and request.method not in allowed:
            return JSONResponse({"detail": "Method Not Allowed"}, status_code=405,
                                headers={"Allow": ", ".join(allowed)})  # fmt: skip
    return await http_exception_handler(request, exc)


def _allowed_methods(request: Request) -> list[str]:
    """The methods /openapi.json lists at the request's path."""
    app = request.app
    paths = getattr(app.state, "documented_paths", None)
    if paths is None:
        paths = app.state.documented_paths = [
            (re.compile(re.sub(r"\\{[^/]+?\\}", "[^/]+", re.escape(path)) + "$"),
             sorted(method.upper() for method in item))
            for path, item in app.openapi().get("paths", {}).items()
        ]  # fmt: skip
    path = request.url.path
    return next((methods for pattern, methods in paths if pattern.match(path)), [])


# -- the settings' bounds in the document -------------------------------------------------


def _with_ttl_bounds(document: dict[str, Any], settings: Settings) -> dict[str, Any]:
    schemas = document.get("components", {}).get("schemas", {})
    for name in _TTL_BODIES:
        ttl = schemas.get(name, {}).get("properties", {}).get("ttl_s")
        if ttl is None:
            continue
        for option in ttl.get("anyOf", [ttl]):
            if option.get("type") == "number":
                option.pop("exclusiveMinimum", None)
                option["minimum"] = settings.lease_ttl_min_s
                option["maximum"] = settings.lease_ttl_max_s
    return document
