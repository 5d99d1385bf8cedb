"""One envelope, checked where the link sends: a take-off, a reposition, a go-to, a setpoint
and sticks beyond it are refused with the same reason, field and limit by a Python program
driving the link's Vehicle, by REST, by the control socket, by the fleet edge and by the
Python client, over one server and its simulated quad."""

from __future__ import annotations

import json
from collections.abc import AsyncIterator, Coroutine
from dataclasses import dataclass
from typing import Any

import pytest
import pytest_asyncio
from websockets.asyncio.client import connect

from server.fleet.edge_api import EdgeApi
from server.fleet.edge_calls import EdgeCalls
from server.link import SetpointRejected, Sticks, Vehicle, intents
from server.link.codec.geo import geodetic_from_ned_m
from server.link.codec.setpoints import VelocityNed
from skyhelm_client import AsyncSkyHelm, InvalidInput
from tests.api.conftest import PILOT
from tests.api.test_ws import Served, receive_until, served

pytestmark = pytest.mark.asyncio(loop_scope="module")

VEHICLE = "/api/v1/vehicles/1"
FAR_M = 600.0  # north of home: beyond the default envelope's 500 m


@dataclass(frozen=True)
class Move:
    """One move beyond the envelope: the link's call, and the API's name and body for it."""

    name: str
    method: str
    path: str
    body: dict[str, Any]


def _moves(vehicle: Vehicle) -> list[Move]:
    home = vehicle.home
    assert home is not None
    far_lat, far_lon, _ = geodetic_from_ned_m((FAR_M, 0.0, 0.0), home.lat_deg, home.lon_deg,
                                              home.alt_amsl_m)  # fmt: skip
    return [
        Move("takeoff", "POST", "/takeoff", {"altitude_m": 5000.0}),
        Move("reposition", "POST", "/reposition", {"lat_deg": far_lat, "lon_deg": far_lon,
                                           "alt_rel_m": 10.0}),
        Move("reposition_high", "POST", "/reposition", {
            "lat_deg": home.lat_deg, "lon_deg": home.lon_deg, "alt_rel_m": 500.0}),
        Move("goto", "POST", "/intents/goto", {"lat_deg": far_lat, "lon_deg": far_lon,
                                       "alt_rel_m": 10.0}),
        Move("offset", "POST", "/intents/offset", {"north_m": 0.0, "east_m": 0.0,
                                                   "up_m": 300.0}),
        Move("velocity", "PUT", "/intents/velocity", {"frame": "ned", "north_m_s": 20.0,
                                                      "east_m_s": 0.0}),
        Move("setpoint", "PUT", "/setpoint", {"type": "velocity_ned", "north_m_s": 20.0,
                                              "east_m_s": 0.0, "down_m_s": 0.0}),
    ]


def _link_call(vehicle: Vehicle, move: Move) -> Coroutine[Any, Any, object]:
    """The move as a program using server.link makes it."""
    b = move.body
    if move.name == "takeoff":
        return vehicle.takeoff(altitude_rel_m=b["altitude_m"])
    if move.name.startswith("reposition"):
        return vehicle.reposition(b["lat_deg"], b["lon_deg"], alt_rel_m=b["alt_rel_m"])
    if move.name == "goto":
        return intents.goto(
            vehicle, lat_deg=b["lat_deg"], lon_deg=b["lon_deg"], alt_rel_m=b["alt_rel_m"]
        )
    if move.name == "offset":
        return intents.offset(vehicle, north_m=b["north_m"], east_m=b["east_m"], up_m=b["up_m"])
    if move.name == "velocity":
        return intents.velocity(vehicle, frame="ned", x_m_s=b["north_m_s"], y_m_s=0.0)
    return vehicle.set_setpoint(VelocityNed(b["north_m_s"], b["east_m_s"], b["down_m_s"]))


async def _refused_by_link(vehicle: Vehicle, move: Move) -> dict[str, Any]:
    """What the link itself says to the move."""
    call = _link_call(vehicle, move)
    with pytest.raises(SetpointRejected) as refused:
        await call
    exc = refused.value
    return {"reason": exc.reason, "field": exc.field, "limit": exc.limit}


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def quad() -> AsyncIterator[Served]:
    async with served() as s:
        yield s


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def refusals(quad: Served) -> list[tuple[Move, dict[str, Any]]]:
    """Each move and the link's refusal of it; the vehicle is left on the ground, disarmed,
    with nothing streamed: nothing was sent."""
    vehicle = quad.api.vehicle()
    found = [(move, await _refused_by_link(vehicle, move)) for move in _moves(vehicle)]
    assert not vehicle.streamer_active
    assert not vehicle.telemetry.armed
    return found


async def test_the_link_names_the_limit(refusals: list[tuple[Move, dict[str, Any]]]) -> None:
    by_name = {move.name: refused for move, refused in refusals}
    assert by_name["takeoff"] == {
        "reason": "takeoff altitude above the envelope", "field": "altitude_m", "limit": 120.0}
    assert by_name["reposition"]["reason"].startswith(
        "reposition outside the envelope: distance_m 600.0 > max_distance_m 500")
    assert (by_name["reposition"]["field"], by_name["reposition"]["limit"]) == ("lat_deg", 500.0)
    assert (by_name["reposition_high"]["field"], by_name["reposition_high"]["limit"]) == (
        "alt_rel_m", 120.0)
    assert by_name["goto"]["reason"].startswith("goto outside the envelope: distance_m 600.0")
    assert by_name["offset"]["field"] == "up_m"
    assert by_name["velocity"]["limit"] == 12.0
    assert by_name["setpoint"] == by_name["velocity"]  # an intent is a setpoint here


async def test_sticks_beyond_their_travel_are_refused_by_the_link() -> None:
    with pytest.raises(SetpointRejected) as refused:
        Sticks(pitch=1.5)
    assert (refused.value.field, refused.value.limit) == ("pitch", 1.0)
    assert refused.value.reason == "pitch 1.5 outside its travel -1..1"
    with pytest.raises(SetpointRejected) as low:
        Sticks(throttle=-0.1)
    assert (low.value.field, low.value.limit) == ("throttle", 0.0)


async def test_rest_answers_the_links_refusal(
    quad: Served, refusals: list[tuple[Move, dict[str, Any]]]
) -> None:
    api = quad.api
    await api.take_control()
    try:
        for move, refused in refusals:
            response = await api.client.request(
                move.method, f"{VEHICLE}{move.path}", json=move.body, headers=api.lease_headers)
            assert response.status_code == 422, (move.name, response.text)
            assert response.json()["detail"] == refused, move.name
    finally:
        await api.client.delete(f"{VEHICLE}/control", headers=api.lease_headers)


async def test_the_control_socket_answers_the_links_refusal(
    quad: Served, refusals: list[tuple[Move, dict[str, Any]]]
) -> None:
    async with connect(quad.url("control", vehicle=1)) as ws:
        await receive_until(ws, {"type": "lease"})
        for request_id, (move, refused) in enumerate(refusals, start=1):
            if move.name == "setpoint":
                message = {"type": "setpoint", "setpoint": move.body}
            else:
                message = {"type": "command", "name": move.path.rsplit("/", 1)[-1],
                           "args": move.body}  # fmt: skip
            await ws.send(json.dumps({**message, "id": request_id}))
            answer = await receive_until(ws, {"type": "result", "id": request_id})
            assert answer["status"] == 422, (move.name, answer)
            assert answer["body"]["detail"] == refused, move.name


async def test_the_fleet_edge_answers_the_links_refusal(
    quad: Served, refusals: list[tuple[Move, dict[str, Any]]]
) -> None:
    app = quad.api.app
    edge = EdgeApi(EdgeCalls(app.state.api, app.state.publishers), "skyhelm/envelope/api")
    auth = {"authorization": f"Bearer {PILOT}"}

    async def call(method: str, path: str, body: Any, lease: str | None = None) -> Any:
        headers = {**auth, "x-lease-id": lease} if lease else auth
        return await edge.run(json.dumps({"method": method, "path": f"{VEHICLE}{path}",
                                           "headers": headers, "body": body}).encode())

    taken = await call("POST", "/control", {"client_name": "edge"})
    assert taken["status"] == 200, taken
    lease = taken["body"]["lease_id"]
    try:
        for move, refused in refusals:
            reply = await call(move.method, move.path, move.body, lease)
            assert reply["status"] == 422, (move.name, reply)
            assert reply["body"]["detail"] == refused, move.name
    finally:
        await call("DELETE", "/control", None, lease)
        await edge.close()


async def test_the_python_client_raises_the_links_refusal(
    quad: Served, refusals: list[tuple[Move, dict[str, Any]]]
) -> None:
    async with AsyncSkyHelm(f"http://{quad.host}/?token={PILOT}") as sky:
        await sky.acquire(ttl_s=30, client_name="envelope")
        calls = {
            "takeoff": lambda b: sky.takeoff(**b),
            "reposition": lambda b: sky.reposition(**b),
            "reposition_high": lambda b: sky.reposition(**b),
            "goto": lambda b: sky.goto(**b),
            "offset": lambda b: sky.offset(**b),
            "velocity": lambda b: sky.velocity(**b),
            "setpoint": lambda b: sky.set_setpoint(b),
        }
        try:
            for move, refused in refusals:
                with pytest.raises(InvalidInput) as invalid:
                    await calls[move.name](move.body)
                got = {"reason": invalid.value.reason, "field": invalid.value.field,
                       "limit": invalid.value.limit}  # fmt: skip
                assert got == refused, move.name
        finally:
            await sky.release()
