"""Intents: what the pilot means, decided in the server (``server.link.intents``) so that
the page, scripts and the control socket fly the same way and meet the same checks.

Each answers ``IntentOut``: the setpoint it streams, or the vehicle's answer to the command
it sent (then with that command's status: 409 refused, 504 no answer). Moves outside the
envelope are a 422 naming the input and the limit, before anything is sent.

There is one route per intent of :data:`server.control.operations.INTENTS`, at the wire's
method and path, taking the table's body, named and described by the intent's function:
adding an intent touches the wire's table (and its body) and the operation, not this
module."""

from __future__ import annotations

import inspect
from collections.abc import Awaitable, Callable

from fastapi import APIRouter
from fastapi.responses import JSONResponse
from pydantic import BaseModel

from server.control import operations
from server.http.context import ApiContext
from server.http.deps import Context, ControlledVehicle
from server.http.errors import COMMAND_RESPONSES, command_status
from server.http.routing import body_parameter, route_options
from server.link import Vehicle
from skyhelm_wire.calls import API_PREFIX, CALL

router = APIRouter(prefix=API_PREFIX, tags=["intents"], responses=COMMAND_RESPONSES)


async def answer_intent(
    context: ApiContext, vehicle: Vehicle, name: str, body: BaseModel | None
) -> JSONResponse:
    answer = await operations.answer_intent(context.deadman, vehicle, name, body)
    return JSONResponse(answer.body, status_code=command_status(answer.outcome))


_Endpoint = Callable[..., Awaitable[JSONResponse]]


def _endpoint(name: str) -> _Endpoint:
    """The route of the intent ``name``: its parameters the controlled vehicle, the API's
    context and the table's body; its name and description the intent function's."""

    async def endpoint(
        vehicle: Vehicle, context: ApiContext, body: BaseModel | None = None
    ) -> JSONResponse:
        return await answer_intent(context, vehicle, name, body)

    keyword = inspect.Parameter.POSITIONAL_OR_KEYWORD
    parameters = [
        inspect.Parameter("vehicle", keyword, annotation=ControlledVehicle),
        inspect.Parameter("context", keyword, annotation=Context),
    ]
    body = body_parameter(CALL[name])
    if body is not None:
        parameters.append(body)
    # FastAPI reads a route's parameters from its signature: this one is built from the table.
    endpoint.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
        parameters, return_annotation=JSONResponse
    )
    run = operations.INTENTS[name].run
    endpoint.__name__ = endpoint.__qualname__ = run.__name__
    endpoint.__doc__ = run.__doc__
    return endpoint


def _add_routes() -> None:
    for name in operations.INTENTS:
        call = CALL[name]
        router.add_api_route(call.route, _endpoint(name), **route_options(call, {}))


_add_routes()
