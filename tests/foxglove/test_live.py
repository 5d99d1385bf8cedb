"""A flight of the simulated vehicle seen through Foxglove: a foxglove.websocket.v1 client
on the app's proxied path gets every kind of channel, each message read by its own schema;
no token, no socket."""

from __future__ import annotations

from collections.abc import AsyncIterator
from dataclasses import dataclass

import pytest
import pytest_asyncio
import websockets

from server.control.publisher import StatePublisher
from server.foxglove import FoxgloveBridge
from tests.api.conftest import OBSERVER, PILOT, Api, api_for, sim_cluster
from tests.foxglove.ws_client import FoxgloveClient, Received, foxglove_client
from tests.serving import uvicorn_serving
from tests.waiting import eventually

pytestmark = pytest.mark.asyncio(loop_scope="module")

PREFIX = "/vehicle_1"
# one of each kind a Foxglove panel reads, by topic: schema name
EXPECTED = {
    f"{PREFIX}/state": "skyhelm.VehicleState",
    f"{PREFIX}/health": "skyhelm.Health",
    f"{PREFIX}/mavlink/ATTITUDE": "mavlink.ATTITUDE",
    f"{PREFIX}/mavlink/GLOBAL_POSITION_INT": "mavlink.GLOBAL_POSITION_INT",
    f"{PREFIX}/sent/SET_POSITION_TARGET_LOCAL_NED": "mavlink.SET_POSITION_TARGET_LOCAL_NED",
    f"{PREFIX}/log": "foxglove.Log",
    f"{PREFIX}/location": "foxglove.LocationFix",
    f"{PREFIX}/tf": "foxglove.FrameTransform",
    f"{PREFIX}/pose": "foxglove.PoseInFrame",
}


@dataclass
class Flight:
    api: Api
    host: str
    bridge: FoxgloveBridge


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def flight() -> AsyncIterator[Flight]:
    async with (
        sim_cluster("quad") as sim,
        api_for(sim, foxglove_port=0) as api,
        uvicorn_serving(api.app) as host,
    ):
        await api.wait_ready()
        yield Flight(api, host, api.app.state.foxglove)


async def fly_offboard(api: Api) -> None:
    await api.take_control()
    assert (await api.control("arm", {"force": False})).status_code == 200
    assert (await api.control("takeoff", {"altitude_m": 4.0})).status_code == 200
    await api.wait_state(lambda s: s["position_ned"]["down_m"] < -3.0, 15.0, "climb to 3 m")
    start = await api.control(
        "offboard/start",
        {"setpoint": {"type": "position_ned", "north_m": 2.0, "east_m": 0.0, "down_m": -4.0}},
    )
    assert start.status_code == 200, start.text


async def _all_kinds(client: FoxgloveClient) -> Received | None:
    await client.subscribe(lambda channel: True)  # channels appear as their messages do
    received = client.received
    return received if all(received.messages.get(topic) for topic in EXPECTED) else None


async def _logged(client: FoxgloveClient, word: str) -> bool:
    """Whether a log message with ``word`` came."""
    return any(word in log.message for log in client.received.messages.get(f"{PREFIX}/log", []))


async def _subscribed_to_log(client: FoxgloveClient) -> bool:
    """Subscribed to the log and the subscription taken (a message sent before then, such as
    the arming's, would never come)."""
    await client.subscribe(lambda channel: True)
    return client.taken(f"{PREFIX}/log")


async def test_a_foxglove_client_gets_every_channel_kind_with_valid_schemas(
    flight: Flight,
) -> None:
    url = f"ws://{flight.host}/api/v1/foxglove?token={OBSERVER}"
    publisher = flight.api.app.state.publishers.for_vehicle(flight.api.vehicle())
    assert publisher.consumers == 0  # no reader of the state channel, no state taken for it
    async with foxglove_client(url) as client:
        # the events of the flight go to the log as they happen: subscribe first
        await eventually(lambda: _subscribed_to_log(client), 10.0, "the log subscribed")
        await fly_offboard(flight.api)
        received = await eventually(lambda: _all_kinds(client), 20.0, "every channel kind")
        # the arming's event may come after the first message of every kind (1 Hz HEARTBEAT)
        await eventually(lambda: _logged(client, "armed"), 10.0, "the arming in the log")
        assert publisher.consumers == 1
    await eventually(lambda: _no_consumer(publisher), 5.0, "the state read no more")
    assert received.server_info is not None
    topics = received.topics()
    for topic, schema_name in EXPECTED.items():
        assert topics[topic]["schemaName"] == schema_name, topics[topic]
    state = received.messages[f"{PREFIX}/state"][-1]
    assert state["id"] == 1
    assert state["armed"] is True
    setpoint = received.messages[f"{PREFIX}/sent/SET_POSITION_TARGET_LOCAL_NED"][-1]
    assert (setpoint["x"], setpoint["z"]) == (pytest.approx(2.0), pytest.approx(-4.0))
    fix = received.messages[f"{PREFIX}/location"][-1]
    assert fix.latitude == pytest.approx(state["global"]["lat_deg"], abs=1e-4)
    transform = received.messages[f"{PREFIX}/tf"][-1]
    assert (transform.parent_frame_id, transform.child_frame_id) == ("map", "vehicle_1")
    assert transform.translation.z > 2.0  # ENU: up is positive
    texts = [log.message for log in received.messages[f"{PREFIX}/log"]]
    assert any("armed" in text for text in texts), texts


async def test_a_missing_or_wrong_token_is_refused(flight: Flight) -> None:
    for query in ("", "?token=wrong-token-value"):
        with pytest.raises(websockets.exceptions.InvalidStatus) as refused:
            async with foxglove_client(f"ws://{flight.host}/api/v1/foxglove{query}"):
                pass
        assert refused.value.response.status_code == 403
    async with foxglove_client(
        f"ws://{flight.host}/api/v1/foxglove", Authorization=f"Bearer {PILOT}"
    ) as client:
        await eventually(lambda: _advertised(client), 5.0, "channels advertised")


async def _no_consumer(publisher: StatePublisher) -> bool:
    return publisher.consumers == 0


async def _advertised(client: FoxgloveClient) -> bool:
    return bool(client.received.channels)
