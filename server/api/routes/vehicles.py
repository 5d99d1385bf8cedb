"""Reading vehicles: the list, one vehicle's full state, its streamer statistics."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request, Response

from server.control.publishers import StatePublishers
from server.control.vehicle_ops import state_json, stream_out
from server.control.views import summary_dict
from server.http.deps import Context, KnownVehicle, Reader
from server.http.errors import AUTH_RESPONSES, READ_RESPONSES
from server.http.routing import route
from server.http.schemas import StreamOut
from skyhelm_wire.calls import API_PREFIX, CALL

router = APIRouter(prefix=API_PREFIX, tags=["vehicles"])


@route(router, CALL["vehicles"], responses=AUTH_RESPONSES)
async def list_vehicles(context: Context, _: Reader) -> list[dict[str, Any]]:
    return [summary_dict(vehicle.snapshot()) for vehicle in context.registry.all()]


@route(router, CALL["state"], responses=READ_RESPONSES)
async def get_vehicle_state(vehicle: KnownVehicle, request: Request) -> Response:
    """The state publisher's latest encoding (the one the telemetry sockets send), with
    the lease as it is now."""
    publishers: StatePublishers = request.app.state.publishers
    return Response(state_json(publishers, vehicle), media_type="application/json")


@route(router, CALL["stream"], responses=READ_RESPONSES)
async def get_stream_stats(vehicle: KnownVehicle) -> StreamOut:
    """Setpoint streamer figures, measured since the stream last started."""
    return stream_out(vehicle)
