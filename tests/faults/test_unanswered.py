"""A command or parameter call that gets no answer says so (504, result TIMEOUT) and nothing
more: it never guesses "refused" or "done". Whether the vehicle acted is left to the state,
which tells the truth once the link is back: a command whose ACKs were all lost was carried
out; one that never reached the vehicle was not."""

from __future__ import annotations

from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import pytest

from sim.process.runner import SimCluster
from tests.api.conftest import Api, sim_cluster
from tests.faults.conftest import api_through, vehicle_behind_proxy
from tests.waiting import wait_for
from tools.faultproxy import FaultProxy


@dataclass
class Rig:
    api: Api
    proxy: FaultProxy
    sim: SimCluster

    @property
    def commander(self) -> Any:
        return self.sim.instances[0].vehicle.commander


@pytest.fixture
async def rig() -> AsyncIterator[Rig]:
    # real time: the vehicle disarms by itself COM_DISARM_PRFLT after arming on the ground,
    # which at 8x would fall inside a 2 s unanswered command
    # and a command tries for 2 s: the vehicle must not be declared lost meanwhile
    async with (
        sim_cluster("quad", speed=1.0) as sim,
        vehicle_behind_proxy(sim) as proxy,
        api_through(proxy, sim, heartbeat_timeout_s=10.0, silence_timeout_s=10.0) as api,
    ):
        await api.wait_ready()
        await api.take_control()
        yield Rig(api, proxy, sim)


def assert_timeout(response: Any) -> None:
    assert response.status_code == 504, response.text
    body = response.json()
    assert body["command"] == "MAV_CMD_COMPONENT_ARM_DISARM"
    assert body["result"] == "TIMEOUT"
    assert body["result_code"] is None  # no MAV_RESULT was received, none is made up


async def test_a_command_whose_acks_are_lost_answers_504_though_the_vehicle_acted(
    rig: Rig,
) -> None:
    rig.proxy.partition(60.0, "to_server")
    answer = await rig.api.control("arm")
    assert_timeout(answer)
    assert rig.commander.armed  # the vehicle did arm: only its answers were lost
    rig.proxy.heal()
    await rig.api.wait_state(lambda s: s["armed"], 10.0, "the state to show the arming")


async def test_a_command_that_never_arrives_answers_504_and_nothing_happened(rig: Rig) -> None:
    rig.proxy.partition(60.0, "to_vehicle")
    answer = await rig.api.control("arm")
    assert_timeout(answer)
    assert not rig.commander.armed
    rig.proxy.heal()
    retried = await rig.api.control("arm")
    assert retried.status_code == 200, retried.text
    assert rig.commander.armed


async def test_a_parameter_read_with_no_answer_is_a_504_naming_it(rig: Rig) -> None:
    before = rig.proxy.counters()["to_vehicle"].partitioned
    rig.proxy.partition(60.0, "to_server")
    answer = await rig.api.client.get("/api/v1/vehicles/1/params/MIS_TAKEOFF_ALT")
    assert answer.status_code == 504, answer.text
    assert "MIS_TAKEOFF_ALT" in answer.json()["detail"]["reason"]
    # the requests did go out (4 tries), only the answers were cut
    await wait_for(lambda: rig.proxy.counters()["to_server"].partitioned > 0, 5.0,
                   "answers dropped by the partition")
    assert rig.proxy.counters()["to_vehicle"].partitioned == before
