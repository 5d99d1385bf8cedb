"""Ready to fly through the API, on the simulated vehicle: not ready with PX4's reason just
after boot, ready once its checks pass, and judged again for the mode it is put in."""

from __future__ import annotations

from typing import Any

from sim.process.runner import SimCluster
from tests.api.conftest import Api, api_for
from tests.waiting import eventually

NO_POSITION = "Navigation error: No valid global position estimate"
NO_LOCAL_POSITION = "Navigation error: No valid position estimate"
NO_OFFBOARD_SIGNAL = "No offboard signal"
NOT_SUITABLE = "Mode not suitable for arming"
# slower than real time, so the not-ready time after boot (3 s of sim time, as PX4 SITL's
# first seconds) outlasts the server's first look at the vehicle and its events metadata
BOOT_SPEED = 0.5


async def test_not_ready_with_px4s_reason_after_boot_then_ready() -> None:
    async with SimCluster("quad", count=1, speed=BOOT_SPEED) as sim, api_for(sim) as api:
        seen: list[dict[str, Any]] = []

        async def ready() -> dict[str, Any] | None:
            checks = (await api.state())["arming_checks"]
            if checks is not None and checks["ready"] is not None:
                seen.append(checks)
            return checks if checks is not None and checks["ready"] else None

        shown = await eventually(ready, 30.0, "ready to fly")

        not_ready = [c for c in seen if c["ready"] is False and c["source"] == "events"]
        assert not_ready, f"never seen not ready from PX4's report: {seen[:3]}"
        first = not_ready[0]
        assert first["mode"] == "HOLD"
        # as PX4 v1.16 SITL reports it after boot: no position estimate, local nor global
        errors = [r["text"] for r in first["reasons"] if r["severity"] == "ERROR"]
        assert errors == [NO_LOCAL_POSITION, NO_POSITION]
        reason = next(r for r in first["reasons"] if r["text"] == NO_POSITION)
        assert reason["severity"] == "ERROR"
        assert reason["component"] == "Global position estimate"
        assert shown["source"] == "events"
        assert all(r["severity"] != "ERROR" for r in shown["reasons"]), shown["reasons"]


async def test_ready_is_judged_for_the_mode_flown(quad_api: Api) -> None:
    api = quad_api
    await api.wait_state(lambda s: (s["arming_checks"] or {}).get("ready") is True
                         and s["arming_checks"]["source"] == "events", 15.0, "ready")  # fmt: skip
    await api.take_control()
    assert (await api.control("mode", {"mode": "OFFBOARD"})).status_code == 200

    state = await api.wait_state(lambda s: s["arming_checks"]["mode"] == "OFFBOARD", 10.0,
                                 "judged in OFFBOARD")  # fmt: skip

    checks = state["arming_checks"]
    assert checks["ready"] is False
    # the error first; warnings and notices of every mode after it
    errors = [r["text"] for r in checks["reasons"] if r["severity"] == "ERROR"]
    assert errors == [NO_OFFBOARD_SIGNAL]
    assert checks["reasons"][0]["text"] == NO_OFFBOARD_SIGNAL
    assert checks["reasons"][0]["modes"] == ["OFFBOARD"]
    assert "OFFBOARD" not in checks["can_arm_modes"]
    assert "HOLD" in checks["can_arm_modes"]
    # (`arm` itself would switch to HOLD first: PX4 refuses OFFBOARD for want of a stream,
    # not for a fault; tests/link/test_arming_modes.py)
    assert (await api.control("mode", {"mode": "HOLD"})).status_code == 200
    state = await api.wait_state(lambda s: s["arming_checks"]["mode"] == "HOLD", 10.0, "HOLD")
    assert state["arming_checks"]["ready"] is True
    assert NO_OFFBOARD_SIGNAL in [r["text"] for r in state["arming_checks"]["other_reasons"]]


async def test_after_an_offboard_flight_lands_arm_switches_to_hold_first(quad_api: Api) -> None:
    api = quad_api
    await api.wait_ready()
    await api.take_control()
    assert (await api.control("arm")).status_code == 200
    assert (await api.control("takeoff", {"altitude_m": 3.0})).status_code == 200
    await api.wait_state(lambda s: s["mode"] == "HOLD" and s["global"]["alt_rel_m"] > 2.5, 30.0,
                         "hovering")  # fmt: skip
    here = (await api.state())["position_ned"]
    setpoint = {"type": "position_ned", "north_m": here["north_m"], "east_m": here["east_m"],
                "down_m": here["down_m"]}  # fmt: skip
    started = await api.control("offboard/start", {"setpoint": setpoint})
    assert started.status_code == 200, started.text
    assert (await api.control("land")).status_code == 200

    # landed and disarmed, PX4 sits in LAND or back in the pilot's OFFBOARD, where it will
    # not arm: the only failing checks are the mode's own, and Arm switches to HOLD first
    state = await api.wait_state(
        lambda s: not s["armed"] and s["landed_state"] == "ON_GROUND"
        and s["arming_checks"]["mode"] in ("LAND", "OFFBOARD")
        and s["arming_checks"]["verdict"] is not None, 60.0, "landed, disarmed",
    )  # fmt: skip
    checks = state["arming_checks"]
    assert checks["ready"] is False, checks
    assert checks["verdict"] == "arm_switches_mode", checks
    assert checks["arm_switches_to"] == "HOLD"
    told = {r["text"] for r in checks["reasons"]}
    assert NOT_SUITABLE in told if checks["mode"] == "LAND" else NO_OFFBOARD_SIGNAL in told
    assert (await api.control("arm")).status_code == 200
    armed = await api.wait_state(lambda s: s["armed"], 5.0, "armed")
    assert armed["mode"] == "HOLD"
    assert (await api.control("disarm")).status_code == 200


async def test_modes_px4_will_not_arm_in_are_answered_so_from_hold(quad_api: Api) -> None:
    api = quad_api
    state = await api.wait_state(
        lambda s: (s["arming_checks"] or {}).get("verdict") == "ready" and s["mode"] == "HOLD"
        and s["arming_checks"]["source"] == "events", 15.0, "ready in HOLD from PX4's report",
    )  # fmt: skip
    checks = state["arming_checks"]
    assert checks["waiting_for"] == []
    for mode in ("LAND", "RTL"):
        assert mode not in checks["can_arm_modes"]
        told = [r for r in checks["other_reasons"] if mode in r["modes"]]
        assert NOT_SUITABLE in [r["text"] for r in told], checks
    assert {"HOLD", "TAKEOFF"} <= set(checks["can_arm_modes"])


async def test_not_ready_until_home_and_a_position_are_known() -> None:
    async with SimCluster("quad", count=1, speed=BOOT_SPEED) as sim, api_for(sim) as api:
        seen: list[dict[str, Any]] = []

        async def ready() -> dict[str, Any] | None:
            state = await api.state()
            checks = state["arming_checks"]
            if checks is not None and checks["verdict"] is not None:
                seen.append({**checks, "home": state["home"]})
            return state if checks is not None and checks["verdict"] == "ready" else None

        shown = await eventually(ready, 30.0, "ready to fly")

        assert shown["home"] is not None
        assert shown["global"] is not None
        assert all(c["home"] is not None for c in seen if c["verdict"] == "ready")
        waiting = [c for c in seen if c["waiting_for"]]
        assert waiting, f"never told it waits for home or a position: {seen[:3]}"
        assert all(c["verdict"] == "not_ready" for c in waiting)
        # home may come with the first HEARTBEAT (as on PX4), the position estimate after it
    assert {"home position", "position estimate"} & set(waiting[0]["waiting_for"])
