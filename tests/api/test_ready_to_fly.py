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
