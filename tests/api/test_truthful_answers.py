"""Truthful answers through the REST API, against the simulated vehicle: a repeated setpoint
PUT renews the stream without extra sends, OFFBOARD that PX4 accepts but does not enter is
asked once more and then refused with the mode seen, a takeoff after PX4 disarmed itself
arms again and climbs."""

from __future__ import annotations

import math
import time
from collections.abc import AsyncIterator
from typing import Any

import pytest

from server.link import Vehicle
from tests.api.conftest import Api, api_for, sim_cluster
from tests.waiting import wait_for

STREAM_RATE_HZ = 50.0
RENEWALS = 40
SETPOINT = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -2.0}


@pytest.fixture
async def api() -> AsyncIterator[Api]:
    async with (
        sim_cluster("quad") as sim,
        api_for(sim, rate_hz=STREAM_RATE_HZ, lease_ttl_s=60.0) as api,
    ):
        await api.wait_ready()
        await api.take_control()
        yield api


def _vehicle(api: Api) -> Vehicle:
    vehicle: Vehicle | None = api.app.state.api.registry.get(1)
    assert vehicle is not None
    return vehicle


async def test_put_of_the_streamed_setpoint_renews_it_without_an_extra_send(
    api: Api, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the simulated vehicle's receiver notes when each setpoint arrives
    receiver = api.inst.vehicle.receiver
    arrivals: list[float] = []
    handle = receiver.handle

    def noting(link: Any, msg: Any) -> None:
        if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            arrivals.append(time.monotonic())
        handle(link, msg)

    monkeypatch.setattr(receiver, "handle", noting)
    assert (await api.control("setpoint", SETPOINT)).status_code == 200
    await wait_for(lambda: len(arrivals) >= 1, 2.0, "the first setpoint")

    for _ in range(RENEWALS):
        assert (await api.control("setpoint", SETPOINT)).status_code == 200
        # paced by the stream: the next PUT once the vehicle has one more setpoint (with an
        # extra send per PUT this would not wait at all)
        seen = len(arrivals)
        await wait_for(lambda n=seen: len(arrivals) > n, 1.0, "the next tick")

    first, last = arrivals[0], arrivals[-1]
    scheduled = 1 + math.floor((last - first) * STREAM_RATE_HZ + 0.5)
    # An extra send per PUT would add RENEWALS; a loaded machine that delays the receiver
    # bunches a few arrivals together, which shortens the span by a tick or two.
    assert len(arrivals) <= scheduled + RENEWALS // 8, (len(arrivals), scheduled)
    assert last - first >= (len(arrivals) - 3 - RENEWALS // 8) / STREAM_RATE_HZ


async def test_offboard_accepted_but_not_entered_is_retried_once_and_then_409(api: Api) -> None:
    vehicle = _vehicle(api)
    vehicle.mode_confirm_timeout_s = 1.0
    vehicle.offboard_prestream_s = 0.2
    # one try per ask: an ACK that a busy machine delivers late must not bring a second try
    # of the same ask, which the sim would count as one more request lost
    vehicle.commands.timeout_s = 5.0
    commander = api.inst.vehicle.commander

    commander.offboard_requests_lost = 1
    retried = await api.control("offboard/start", {})
    assert retried.status_code == 200, retried.text
    assert retried.json()["result"] == "ACCEPTED"
    assert (await api.control("offboard/stop", {})).status_code == 200

    commander.offboard_requests_lost = 2
    refused = await api.control("offboard/start", {})
    assert refused.status_code == 409, refused.text
    assert refused.json()["result"] == "NOT_CONFIRMED"
    assert refused.json()["reason"] == "accepted twice, but the vehicle still reports HOLD"
    assert commander.offboard_requests_lost == 0


async def test_takeoff_after_px4_disarmed_itself_arms_and_climbs(api: Api) -> None:
    assert (await api.control("arm")).status_code == 200
    await api.wait_state(lambda s: s["armed"], 5.0, "armed")
    # PX4 disarms a vehicle left armed on the ground after COM_DISARM_PRFLT (10 sim s)
    await api.wait_state(lambda s: not s["armed"], 10.0, "PX4's own disarm")

    response = await api.control("takeoff", {"altitude_m": 3.0})

    assert response.status_code == 200, response.text
    assert response.json()["result"] == "ACCEPTED"
    await api.wait_state(lambda s: s["armed"] and s["global"]["alt_rel_m"] > 1.0, 20.0, "climbing")


async def test_an_accepted_arm_or_disarm_is_the_state_when_it_is_answered(api: Api) -> None:
    """PX4 reports arming in its HEARTBEAT, once a second: an ACCEPTED arm answered before
    one came left `armed` false for up to a second (the page's badge said DISARMED under
    "Arm: ACCEPTED"). The answer waits for the vehicle to report it."""
    for path, armed in (("arm", True), ("disarm", False), ("arm", True), ("disarm", False)):
        answer = await api.control(path)
        assert answer.status_code == 200, answer.text
        assert answer.json()["result"] == "ACCEPTED"
        assert (await api.state())["armed"] is armed, path
