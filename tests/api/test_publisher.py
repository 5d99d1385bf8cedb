"""The state publisher on virtual loop time: one encode per tick whatever the number of
consumers, latest wins for a slow consumer, rate tiers honoured, the JSON the API shows."""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import Callable

import pytest

from server.control.publisher import Published, StatePublisher
from server.control.publishers import StatePublishers
from server.control.slots import Slot
from server.control.views import encode_state, state_json, state_message
from server.http.schemas import VehicleStateOut
from server.link.core.state import GlobalState, PositionNedState, VehicleState
from skyhelm_wire.messages import StateMessage
from tests.api.state_fakes import PushingVehicle
from tests.scene.conftest import make_state

pytestmark = pytest.mark.looptime

CHANGE_RATE_HZ = 100.0


def _vehicle(sysid: int = 1) -> PushingVehicle:
    """A vehicle one metre further north at every move."""
    return PushingVehicle(
        lambda v: make_state(sysid=v.sysid, position_ned=PositionNedState(v.moves, 0, 0)), sysid
    )


def _publisher(
    vehicle: PushingVehicle, encode: Callable[[VehicleState], bytes] = encode_state
) -> StatePublisher:
    publisher = StatePublisher(
        vehicle,
        lambda _sysid: ("pilot", 1.0),
        max_rate_hz=50.0,
        encode=encode,
    )
    publisher.start()
    return publisher


async def _fly(vehicle: PushingVehicle, seconds: float) -> None:
    for _ in range(round(seconds * CHANGE_RATE_HZ)):
        vehicle.move()
        await asyncio.sleep(1.0 / CHANGE_RATE_HZ)
    await asyncio.sleep(0.5)  # let held-back and booked deliveries through


async def _read_messages(slot: Slot[Published], into: list[str]) -> None:
    async for published in slot:
        into.append(published.message)


async def _encodes_for(clients: int) -> tuple[int, int, list[list[str]]]:
    vehicle = _vehicle()
    calls: list[VehicleState] = []

    def counting(state: VehicleState) -> bytes:
        calls.append(state)
        return encode_state(state)

    publisher = _publisher(vehicle, counting)
    await asyncio.sleep(0.1)  # started: the clients all get its first tick at subscription
    received: list[list[str]] = [[] for _ in range(clients)]
    readers = [
        asyncio.create_task(_read_messages(publisher.subscribe(50.0), into))
        for into in received
    ]
    await asyncio.sleep(0.1)  # every reader has read the state at subscription
    await _fly(vehicle, 2.0)
    await publisher.close()
    await asyncio.gather(*readers)
    assert publisher.encodes == len(calls)
    return len(calls), publisher.ticks, received


async def test_many_clients_of_one_vehicle_cause_one_encode_per_tick() -> None:
    one, ticks_one, received_one = await _encodes_for(1)
    fifty, ticks_fifty, received = await _encodes_for(50)

    # every client received the same texts, one per tick, and each was encoded once
    assert all(messages == received[0] for messages in received)
    assert (one, fifty) == (len(received_one[0]), len(received[0]))
    assert ticks_one - 2 <= one <= ticks_one
    assert ticks_fifty - 2 <= fifty <= ticks_fifty
    assert 2.0 * 50 - 5 <= ticks_fifty <= 2.0 * 50 + 3  # the 50 Hz tick over 2 s


async def test_snapshots_follow_the_fastest_due_tier_not_the_vehicle() -> None:
    """A vehicle changing 100 times a second, watched only at 4 Hz (the page's map), is
    snapshotted about 4 times a second: with 50 vehicles the snapshots at every change
    were a tenth of the server's time."""
    vehicle = _vehicle()
    snapshots = 0
    take = vehicle.snapshot

    def counted() -> VehicleState:
        nonlocal snapshots
        snapshots += 1
        return take()

    vehicle.snapshot = counted  # type: ignore[method-assign]
    publisher = _publisher(vehicle)
    got: list[str] = []
    reader = asyncio.create_task(_read_messages(publisher.subscribe(4.0), got))
    await asyncio.sleep(0.1)
    before = snapshots
    await _fly(vehicle, 5.0)
    await publisher.close()
    await reader
    assert 4.0 * 5 - 3 <= len(got) <= 4.0 * 5 + 4
    assert snapshots - before <= len(got) + 2
    # and the newest state reached the reader: the last tick is at most one tick old
    assert json.loads(got[-1])["position_ned"]["north_m"] >= vehicle.moves - 100 / 4.0


async def test_a_slow_consumer_gets_the_newest_state_never_a_backlog() -> None:
    vehicle = _vehicle()
    publisher = _publisher(vehicle)
    slot = publisher.subscribe(50.0)
    await anext(slot)  # the state at subscription

    await _fly(vehicle, 1.0)  # 100 changes, ~50 ticks, none read

    newest = await asyncio.wait_for(anext(slot), 1.0)
    assert newest.state.position_ned == PositionNedState(vehicle.moves, 0, 0)
    assert slot.replaced >= 40
    with pytest.raises(TimeoutError):  # nothing queued behind it
        await asyncio.wait_for(anext(slot), 5.0)
    await publisher.close()


@pytest.mark.parametrize("rate_hz", [1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 50.0])
async def test_rate_tiers_are_honoured(rate_hz: float) -> None:
    vehicle = _vehicle()
    publisher = _publisher(vehicle)
    fast: list[str] = []
    asked: list[str] = []
    readers = [
        asyncio.create_task(_read_messages(publisher.subscribe(50.0), fast)),
        asyncio.create_task(_read_messages(publisher.subscribe(rate_hz), asked)),
    ]
    await _fly(vehicle, 10.0)
    await publisher.close()
    await asyncio.gather(*readers)

    # 10 s at the asked rate, plus the state at subscription
    assert 10 * rate_hz - 1 <= len(asked) <= 10 * rate_hz + 2
    assert len(fast) >= 10 * 50 - 5


async def test_rates_above_the_maximum_are_capped() -> None:
    vehicle = _vehicle()
    publisher = _publisher(vehicle)
    received: list[str] = []
    reader = asyncio.create_task(_read_messages(publisher.subscribe(1000.0), received))
    await _fly(vehicle, 2.0)
    await publisher.close()
    await reader
    assert len(received) <= 2 * 50 + 2


async def test_the_scene_watch_gets_each_vehicle_at_its_rate_without_encoding() -> None:
    vehicles = [_vehicle(1), _vehicle(2)]
    publishers = StatePublishers(
        lambda: vehicles,  # type: ignore[arg-type, return-value]
        lambda _sysid: (None, None),
        max_rate_hz=50.0,
    )
    await publishers.start([])
    watch = publishers.watch_states(20.0)
    seen: dict[int, int] = {1: 0, 2: 0}

    async def scene() -> None:
        while True:
            for state in await watch.next_states():
                seen[state.sysid] += 1

    reader = asyncio.create_task(scene())
    await asyncio.gather(*(_fly(vehicle, 5.0) for vehicle in vehicles))
    reader.cancel()
    watch.close()
    encodes = [publishers.for_vehicle(v).encodes for v in vehicles]  # type: ignore[arg-type]
    await publishers.close()

    assert all(5 * 20 - 1 <= count <= 5 * 20 + 2 for count in seen.values()), seen
    assert encodes == [0, 0]


def test_state_json_has_the_api_names_and_null_for_non_finite_numbers() -> None:
    state = make_state(
        global_position=GlobalState(47.0, 8.0, math.nan, 3.0),
        actuator_outputs=(math.inf, 0.5),
        setpoint={"type": "position_ned", "north_m": 1.0, "east_m": 2.0, "down_m": -3.0},
        air_speed_m_s=math.nan,
        telemetry_refused=("SERVO_OUTPUT_RAW",),
    )
    body = encode_state(state)

    rest = json.loads(state_json(state, body, ("pilot", 1.5)))
    assert (rest["id"], rest["type"]) == (1, "QUADROTOR")
    assert rest["global"]["alt_amsl_m"] is None
    assert rest["actuator_outputs"] == [None, 0.5]
    assert rest["air_speed_m_s"] is None
    assert rest["lease"] == {"holder": "pilot", "expires_in_s": 1.5}
    assert not {"mav_type", "global_position", "telemetry_refused"} & set(rest)
    # what the response model shows is what is sent (it adds the setpoint's optional fields)
    shown = VehicleStateOut.model_validate(rest).model_dump(mode="json", by_alias=True)
    assert shown.pop("setpoint").items() >= {**rest}.pop("setpoint").items()
    assert shown == {key: value for key, value in rest.items() if key != "setpoint"}

    message = json.loads(state_message(state, body, (None, None)))
    assert (message["type"], message["vehicle"], message["vehicle_type"]) == (
        "state", 1, "QUADROTOR"
    )
    assert message["telemetry_refused"] == ["SERVO_OUTPUT_RAW"]
    assert message["lease"] == {"holder": None, "expires_in_s": None}
    assert {key: message[key] for key in rest if key not in ("type", "lease")} == {
        key: value for key, value in rest.items() if key not in ("type", "lease")
    }
    # the socket's message is the wire's StateMessage, every key of it declared there
    as_wire = StateMessage.model_validate(message).model_dump(mode="json", by_alias=True)
    assert {key: value for key, value in as_wire.items() if key != "setpoint"} == {
        key: value for key, value in message.items() if key != "setpoint"
    }


async def test_rest_reads_share_the_latest_encoding_with_the_lease_as_it_is_now() -> None:
    vehicle = _vehicle()
    lease = [("first", 1.0)]
    publisher = StatePublisher(vehicle, lambda _sysid: lease[0], max_rate_hz=50.0)

    before = json.loads(publisher.rest_json())
    lease[0] = ("second", 2.0)
    after = json.loads(publisher.rest_json())
    assert publisher.encodes == 1
    assert (before["lease"]["holder"], after["lease"]["holder"]) == ("first", "second")

    vehicle.move()
    assert json.loads(publisher.rest_json())["position_ned"]["north_m"] == 1.0
    assert publisher.encodes == 2
    await asyncio.sleep(0.1)  # older than a tick: the heartbeat age in it has moved on
    publisher.rest_json()
    assert publisher.encodes == 3
