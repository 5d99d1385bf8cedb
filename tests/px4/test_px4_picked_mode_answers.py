"""The ready-to-fly popover's answer for a mode picked in the mode menu, against real PX4
v1.16 SITL: judged from HOLD (the state's can_arm_modes and the checks that concern the
mode, as web/readiness.js shows them), it must be what PX4 answers once it flies that
mode: its own arming-check verdict there, and an arm that PX4 takes or refuses. LAND and
RTL included: PX4's report keeps their can-arm bits while HOLD is flown, yet it will not
arm in them ("Mode not suitable for arming"). Also: the badge's verdict after PX4 was put
there is amber ("arm_switches_mode") exactly for the modes SkyHelm's arm leaves for HOLD."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from tests.px4.conftest import Px4Sitl
from tests.px4.test_px4_arming_modes import _Pilot as _ArmingPilot
from tests.serve_process import Served
from tests.waiting import wait_for_blocking

pytestmark = pytest.mark.px4

# web/modes.js's multicopter menu
MULTICOPTER_MENU = [
    "MANUAL", "STABILIZED", "ACRO", "ALTCTL", "POSCTL", "POSCTL_ORBIT", "OFFBOARD", "HOLD",
    "TAKEOFF", "LAND", "RTL", "MISSION", "FOLLOW_TARGET", "PRECLAND",
]  # fmt: skip
# SkyHelm's arm switches to HOLD from these (server/link/plugins/arming_modes.py)
ARM_SWITCHES = {"RTL", "LAND", "PRECLAND", "FOLLOW_TARGET", "POSCTL_ORBIT", "OFFBOARD"}
# PX4 sends a new arming-check report when its result changes; on SITL it came well
# within this after a mode change
REPORT_S = 6.0


class _Pilot(_ArmingPilot):
    """The arming-modes pilot, renewing its lease on every command (the walk is long)."""

    def __init__(self, served: Served, vehicle: int) -> None:
        super().__init__(served, vehicle, "mode answers")

    def post(self, path: str, body: dict[str, Any] | None = None) -> httpx.Response:
        self.http.put(f"{self.vehicle}/control")  # renew the lease
        return super().post(path, body)

    def checks_in(self, mode: str, done: Any = lambda _c: True) -> dict[str, Any]:
        """The arming checks once PX4's report judges ``mode`` (and ``done`` holds)."""

        def judged() -> dict[str, Any] | None:
            checks = self.state()["arming_checks"]
            ok = checks and checks["source"] == "events" and checks["mode"] == mode
            return checks if ok and done(checks) else None

        found: dict[str, Any] = wait_for_blocking(f"PX4's report in {mode}", judged, 30.0, 0.2)
        return found


@pytest.fixture(scope="module")
def pilot(px4: Px4Sitl, served_px4: Served) -> Iterator[_Pilot]:
    auth = {"Authorization": f"Bearer {served_px4.pilot_token}"}

    def listed() -> bool:
        answer = httpx.get(f"{served_px4.api}/vehicles", headers=auth)
        return answer.status_code == 200 and px4.sysid in [v["id"] for v in answer.json()]

    wait_for_blocking("PX4 listed", listed, 30.0, 0.2)
    pilot = _Pilot(served_px4, px4.sysid)
    wait_for_blocking(
        "PX4 ready to fly in HOLD",
        lambda: (c := pilot.state().get("arming_checks")) and c["verdict"] == "ready"
        and c["source"] == "events",
        90.0, 0.5,
    )  # fmt: skip
    yield pilot
    pilot.http.close()


def _picked_answer(checks: dict[str, Any], mode: str) -> tuple[bool, list[str]]:
    """What the popover says for a picked mode: can arm, and the checks that concern it
    (PX4 refuses for checks it reports as warnings too: "No manual control input")."""
    reasons = [r["text"] for r in checks["reasons"] + checks["other_reasons"] if mode in r["modes"]]
    return mode in checks["can_arm_modes"], reasons


@pytest.mark.parametrize("mode", MULTICOPTER_MENU)
def test_px4_answers_a_picked_mode_as_the_popover_said(pilot: _Pilot, mode: str) -> None:
    assert pilot.post("/mode", {"mode": "HOLD"}).status_code == 200
    in_hold = pilot.checks_in("HOLD", lambda c: c["ready"] is True)
    can_arm, said = _picked_answer(in_hold, mode)
    # a refusal comes with its reason
    assert can_arm or said, (mode, in_hold)

    switched = pilot.post("/mode", {"mode": mode})
    if switched.status_code != 200:  # PX4 would not even fly it now: nothing to arm in
        assert not can_arm, f"{mode} refused ({switched.text}) but said to arm: {in_hold}"
        return
    deadline = time.monotonic() + REPORT_S
    flown = pilot.checks_in(mode)
    while flown["ready"] != can_arm and time.monotonic() < deadline:
        time.sleep(0.2)  # a real vehicle's report, in real time
        flown = pilot.checks_in(mode)
    print(mode, "picked from HOLD:", can_arm, said, "| PX4 in it:", flown["ready"],
          [(r["text"], r["severity"], r["modes"]) for r in flown["reasons"]],
          flown["verdict"])  # fmt: skip
    assert flown["ready"] == can_arm, (mode, in_hold, flown)
    # PX4's own words for the refusal are the ones the popover gave
    if not can_arm:
        told = {r["text"] for r in flown["reasons"]}
        assert told & set(said), (mode, said, flown["reasons"])
        # the popover's own reason for this mode (not one HOLD shares) is PX4's
        shared = {r["text"] for r in in_hold["reasons"]}
        if set(said) - shared:
            assert told & (set(said) - shared), (mode, said, flown["reasons"])
        expected = "arm_switches_mode" if mode in ARM_SWITCHES else "not_ready"
        assert flown["verdict"] == expected, flown
    else:
        assert flown["verdict"] == "ready", flown

    if mode == "TAKEOFF":
        return  # armed in TAKEOFF, PX4 takes off at once
    armed = pilot.post("/arm")
    if mode in ARM_SWITCHES and not can_arm:
        assert armed.status_code == 200, armed.text
        state = wait_for_blocking("armed", lambda: (s := pilot.state())["armed"] and s, 5.0)
        assert state["mode"] == "HOLD"
    elif can_arm:
        assert armed.status_code == 200, armed.text
        state = wait_for_blocking("armed", lambda: (s := pilot.state())["armed"] and s, 5.0)
        assert state["mode"] == mode
    else:
        assert armed.status_code == 409, armed.text
        assert armed.json()["reason"].startswith("Arming denied"), armed.text
    if pilot.state()["armed"]:
        assert pilot.post("/disarm", {"force": True}).status_code == 200
        wait_for_blocking("disarmed", lambda: not pilot.state()["armed"], 10.0, 0.2)
