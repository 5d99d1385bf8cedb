"""What real PX4 v1.16 does where the simulated vehicle was made to match it
(sim/flight/commander.py) and the server chooses a mode to arm in
(server/link/plugins/arming_modes.py): disarmed, any mode is taken; in RTL, LAND, and
OFFBOARD without a stream PX4 will not arm ("Mode not suitable for arming", "No offboard
signal"); the server's arm leaves such a mode for HOLD, its takeoff goes through TAKEOFF,
and a refusal in the pilot's own mode (MISSION with no mission) stays a 409."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from tests.px4.conftest import Px4Sitl
from tests.serve_process import Served
from tests.waiting import wait_for_blocking

pytestmark = pytest.mark.px4

MAV_RESULT_TEMPORARILY_REJECTED = 1


class _Pilot:
    def __init__(self, served: Served, vehicle: int, client_name: str = "arming modes") -> None:
        self.vehicle = f"/vehicles/{vehicle}"
        self.http = httpx.Client(
            base_url=served.api,
            headers={"Authorization": f"Bearer {served.pilot_token}"},
            timeout=30.0,
        )
        lease = self.http.post(f"{self.vehicle}/control", json={"client_name": client_name})
        lease.raise_for_status()
        self.http.headers["X-Lease-Id"] = lease.json()["lease_id"]

    def post(self, path: str, body: dict[str, Any] | None = None) -> httpx.Response:
        return self.http.post(f"{self.vehicle}{path}", json=body or {})

    def state(self) -> dict[str, Any]:
        state: dict[str, Any] = self.http.get(self.vehicle).json()
        return state

    def disarmed_in(self, mode: str) -> None:
        """From disarmed in HOLD with PX4's checks passing, to ``mode``."""
        wait_for_blocking("disarmed", lambda: not self.state()["armed"], 10.0, 0.5)
        assert self.post("/mode", {"mode": "HOLD"}).status_code == 200
        wait_for_blocking("ready to arm in HOLD", lambda: self.state()["ready_to_arm"], 30.0, 0.5)
        assert self.post("/mode", {"mode": mode}).status_code == 200
        assert self.state()["mode"] == mode

    def landed(self) -> None:
        assert self.post("/land").status_code == 200
        wait_for_blocking("landed and disarmed", lambda: not self.state()["armed"], 90.0, 0.5)


@pytest.fixture(scope="module")
def pilot(px4: Px4Sitl, served_px4: Served) -> Iterator[_Pilot]:
    def listed() -> bool:
        auth = {"Authorization": f"Bearer {served_px4.pilot_token}"}
        answer = httpx.get(f"{served_px4.api}/vehicles", headers=auth)
        assert answer.status_code == 200, answer.text
        return px4.sysid in [v["id"] for v in answer.json()]

    # the server may be up before PX4's first HEARTBEAT reached it
    wait_for_blocking("PX4 listed", listed, 30.0, 0.2)
    pilot = _Pilot(served_px4, px4.sysid)
    # answers 503 until the vehicle has reported; PX4 passes its checks a few seconds in
    wait_for_blocking("PX4 ready to arm", lambda: pilot.state().get("ready_to_arm"), 60.0, 0.5)
    yield pilot
    pilot.http.close()


@pytest.mark.parametrize("mode", ["RTL", "LAND", "OFFBOARD"])
def test_px4_arm_leaves_a_mode_it_will_not_arm_in_for_hold(pilot: _Pilot, mode: str) -> None:
    pilot.disarmed_in(mode)

    armed = pilot.post("/arm")

    assert armed.status_code == 200, armed.text
    state = wait_for_blocking("armed", lambda: (s := pilot.state())["armed"] and s, 5.0)
    assert state["mode"] == "HOLD"
    assert pilot.post("/disarm").status_code == 200


def test_px4_takeoff_from_offboard_disarmed_arms_and_climbs(pilot: _Pilot) -> None:
    pilot.disarmed_in("OFFBOARD")

    answer = pilot.post("/takeoff", {"altitude_m": 3.0})

    assert answer.status_code == 200, answer.text
    wait_for_blocking(
        "climbing", lambda: (pilot.state()["global"] or {}).get("alt_rel_m", 0) > 1.5, 30.0
    )
    pilot.landed()


def test_px4_refusal_in_the_pilots_own_mode_stays_409(pilot: _Pilot) -> None:
    pilot.disarmed_in("MISSION")  # no mission uploaded

    refused = pilot.post("/arm")

    assert refused.status_code == 409, refused.text
    assert refused.json()["result_code"] == MAV_RESULT_TEMPORARILY_REJECTED
    assert refused.json()["reason"].startswith("Arming denied")
    assert pilot.state()["mode"] == "MISSION"
    assert pilot.post("/mode", {"mode": "HOLD"}).status_code == 200


def test_px4_an_accepted_arm_or_disarm_is_the_state_when_it_is_answered(pilot: _Pilot) -> None:
    """PX4 says it is armed in HEARTBEAT, once a second on this link: the answer waits for
    it (asked for at once), so the state read right after says what PX4 does."""
    pilot.disarmed_in("HOLD")
    for path, armed in (("/arm", True), ("/disarm", False), ("/arm", True), ("/disarm", False)):
        answer = pilot.post(path)
        assert answer.status_code == 200, answer.text
        assert pilot.state()["armed"] is armed, path
        assert answer.json()["elapsed_ms"] < 500  # the heartbeat asked for, not the next one
