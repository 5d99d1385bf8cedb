"""VTOL transitions on the simulated standard VTOL, resolved by the reported vtol_state."""

from __future__ import annotations

from tests.api.conftest import api_for, sim_cluster


async def test_vtol_transitions_to_fixed_wing_and_back() -> None:
    async with sim_cluster("vtol") as sim, api_for(sim) as api:
        await api.wait_ready()
        await api.take_control()
        assert (await api.state())["vtol_state"] == "MC"
        assert (await api.control("arm")).status_code == 200
        assert (await api.control("takeoff", {"altitude_m": 20.0})).status_code == 200
        # PX4 refuses the transition until the takeoff hands over to Hold at 20 m
        await api.wait_state(
            lambda s: s["mode"] == "HOLD" and s["position_ned"]["down_m"] < -18.0, 30.0, "climb")

        forward = await api.control("vtol/transition", {"to": "fixed_wing", "wait": True})
        assert forward.status_code == 200, forward.text
        assert forward.json()["command"] == "MAV_CMD_DO_VTOL_TRANSITION"
        assert (await api.state())["vtol_state"] == "FW"

        # In fixed-wing flight PX4 drops velocity setpoints; the API says so up front.
        refused = await api.control(
            "setpoint", {"type": "velocity_ned", "north_m_s": 5.0, "east_m_s": 0.0, "down_m_s": 0.0}
        )
        assert refused.status_code == 422
        assert "fixed wing" in refused.json()["detail"]["reason"]

        back = await api.control("vtol/transition", {"to": "multicopter", "wait": True})
        assert back.status_code == 200, back.text
        assert (await api.state())["vtol_state"] == "MC"
