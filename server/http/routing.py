"""A REST route at its call's method and path (``skyhelm_wire.calls``): the route modules
write each route's handler and its documented answers, never its method or path."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Annotated, Any, TypeVar

from fastapi import APIRouter, Body

from skyhelm_wire.calls import CallSpec

_F = TypeVar("_F", bound=Callable[..., Any])


def route_options(call: CallSpec, options: dict[str, Any]) -> dict[str, Any]:
    """``add_api_route``'s options for ``call``: its method and its answer model (a JSON
    answer; a 204 or a body that is not JSON has none) besides ``options``."""
    answer = {} if call.answer is None or call.answer is bytes else {"response_model": call.answer}
    return {"methods": [call.method], **answer, **options}


def route(router: APIRouter, call: CallSpec, **options: Any) -> Callable[[_F], _F]:
    """Register the decorated handler as ``call``'s route on ``router`` (whose prefix is
    the API's): ``@route(router, CALL["brake"], responses=...)``."""

    def register(handler: _F) -> _F:
        router.add_api_route(call.route, handler, **route_options(call, options))
        return handler

    return register


def body_parameter(call: CallSpec) -> inspect.Parameter | None:
    """A table-made route's body parameter, as the table says: none (``body`` None), the
    body's model (``body_required``), or one that may be left out (every field has a
    default)."""
    if call.body is None:
        return None
    if call.body_required:
        return inspect.Parameter("body", inspect.Parameter.KEYWORD_ONLY, annotation=call.body)
    return inspect.Parameter(
        "body",
        inspect.Parameter.KEYWORD_ONLY,
        annotation=Annotated[call.body | None, Body()],
        default=None,
    )
