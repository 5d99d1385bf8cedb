"""Fan-out timing on virtual loop time: a due tier's tick is the state just after the
vehicle's newest message (its age adds nothing to a client's latency), ticks follow the
consumers' rates rather than the vehicle's message rate, and consumers at different rates
share ticks, each encoded once."""

from __future__ import annotations

import asyncio
import itertools

import pytest

from server.control.publisher import NEXT_MESSAGE_WAIT_SHARE, Published, StatePublisher
from server.control.slots import Slot
from server.link.codec.aio import loop_time_s
from server.link.core.state import PositionNedState
from tests.api.state_fakes import PushingVehicle
from tests.scene.conftest import make_state

pytestmark = pytest.mark.looptime


def _vehicle() -> PushingVehicle:
    return PushingVehicle(
        lambda v: make_state(sysid=v.sysid, position_ned=PositionNedState(v.moves, 0, 0))
    )


def _publisher(vehicle: PushingVehicle) -> StatePublisher:
    publisher = StatePublisher(vehicle, lambda _sysid: ("pilot", 1.0), max_rate_hz=50.0)
    publisher.start()
    return publisher


async def _move_every(vehicle: PushingVehicle, period_s: float, seconds: float) -> list[float]:
    """Moves the vehicle every period_s for seconds; returns the loop time of each move."""
    times = []
    for _ in range(round(seconds / period_s)):
        vehicle.move()
        times.append(loop_time_s())
        await asyncio.sleep(period_s)
    return times


async def _read(slot: Slot[Published], into: list[tuple[float, Published]]) -> None:
    async for published in slot:
        into.append((loop_time_s(), published))


async def test_a_due_tier_sends_the_state_of_the_vehicles_newest_message() -> None:
    vehicle = _vehicle()
    publisher = _publisher(vehicle)
    received: list[tuple[float, Published]] = []
    reader = asyncio.create_task(_read(publisher.subscribe(10.0), received))
    # 33 Hz messages, a 10 Hz consumer: each delivery waits for the next message
    moves_s = await _move_every(vehicle, 0.03, 3.0)
    await publisher.close()
    await reader

    deliveries = received[1:]  # after the state at subscription
    assert 3.0 * 10 - 2 <= len(deliveries) <= 3.0 * 10 + 1
    for got_s, published in deliveries:
        north_m = published.state.position_ned.north_m  # type: ignore[union-attr]
        newest_move_s = moves_s[int(north_m) - 1]
        # the snapshot holds the newest move, taken and read at the moment it came in
        assert [s for s in moves_s if s <= got_s][-1] == newest_move_s
        assert got_s - newest_move_s < 0.002
        assert published.taken_s - newest_move_s < 0.002
    # yet the grid holds the rate: never two deliveries within one message period
    gaps_s = [b[0] - a[0] for a, b in itertools.pairwise(deliveries)]
    assert min(gaps_s) > 0.1 - 0.03 - 0.002


async def test_a_quiet_vehicle_still_gets_its_last_change_out_within_the_slot_wait() -> None:
    vehicle = _vehicle()
    publisher = _publisher(vehicle)
    received: list[tuple[float, Published]] = []
    reader = asyncio.create_task(_read(publisher.subscribe(10.0), received))
    await asyncio.sleep(0.5)
    vehicle.move()  # soon after a slot: the slot wait is for nothing newer
    moved_s = loop_time_s()
    await asyncio.sleep(0.02)
    vehicle.move()
    last_s = loop_time_s()
    await asyncio.sleep(1.0)
    await publisher.close()
    await reader

    after = [(s, p) for s, p in received if s >= moved_s]
    assert after[-1][1].state.position_ned.north_m == 2.0  # type: ignore[union-attr]
    assert after[-1][0] - last_s <= 0.1 + 0.1 * NEXT_MESSAGE_WAIT_SHARE + 0.002
    assert len(after) <= 2  # and nothing resent while the vehicle is silent


async def test_ticks_follow_the_consumers_rate_not_the_vehicles() -> None:
    vehicle = _vehicle()
    publisher = _publisher(vehicle)
    slots = [publisher.subscribe(10.0) for _ in range(20)]
    received: list[list[tuple[float, Published]]] = [[] for _ in slots]
    readers = [asyncio.create_task(_read(s, into)) for s, into in zip(slots, received, strict=True)]
    await _move_every(vehicle, 0.01, 5.0)  # 100 messages a second
    await publisher.close()
    await asyncio.gather(*readers)

    # about 10 snapshots a second, each encoded once for all 20 consumers
    assert 5 * 10 - 2 <= publisher.ticks <= 5 * 10 + 2
    sent = [published for _, published in received[0]]
    assert all([p for _, p in each] == sent for each in received)  # the very same ticks
    texts = {published.message for each in received for _, published in each}
    assert len(texts) == len(sent) == publisher.encodes


async def test_consumers_at_different_rates_share_ticks() -> None:
    vehicle = _vehicle()
    publisher = _publisher(vehicle)
    fast: list[tuple[float, Published]] = []
    slow: list[tuple[float, Published]] = []
    readers = [
        asyncio.create_task(_read(publisher.subscribe(50.0), fast)),
        asyncio.create_task(_read(publisher.subscribe(10.0), slow)),
    ]
    await _move_every(vehicle, 0.01, 2.0)
    for _, published in fast + slow:
        _ = published.message  # what a telemetry socket sends
    await publisher.close()
    await asyncio.gather(*readers)

    fast_ticks = {id(p) for _, p in fast}
    shared = sum(id(p) in fast_ticks for _, p in slow)
    assert shared >= len(slow) - 2  # the slow tier sends ticks the fast one took
    assert publisher.ticks <= 2 * 50 + 3
    assert publisher.encodes <= publisher.ticks


async def test_a_faster_consumer_added_later_gets_its_rate_at_once() -> None:
    vehicle = _vehicle()
    publisher = _publisher(vehicle)
    slow: list[tuple[float, Published]] = []
    fast: list[tuple[float, Published]] = []
    moving = asyncio.create_task(_move_every(vehicle, 0.01, 3.0))
    readers = [asyncio.create_task(_read(publisher.subscribe(0.5), slow))]
    await asyncio.sleep(1.0)  # the publisher now sleeps until the 0.5 Hz slot
    readers.append(asyncio.create_task(_read(publisher.subscribe(50.0), fast)))
    added_s = loop_time_s()
    await asyncio.sleep(1.0)
    counted = [s for s, _ in fast if s <= added_s + 1.0]
    await moving
    await publisher.close()
    await asyncio.gather(*readers)

    assert 50 - 3 <= len(counted) <= 50 + 2
    assert fast[1][0] - added_s <= 0.02 + 0.002
