"""A whole flight by REST against the simulated quad, and every command's real answer."""

from __future__ import annotations

import math

from tests.api.conftest import Api

HOLD_STILL = {"type": "velocity_ned", "north_m_s": 0.0, "east_m_s": 0.0, "down_m_s": 0.0}


def _speed_m_s(state: dict[str, object]) -> float:
    velocity = state["velocity_ned"]
    assert isinstance(velocity, dict)
    return math.hypot(velocity["north_m_s"], velocity["east_m_s"])


def _north_m(state: dict[str, object]) -> float:
    position = state["position_ned"]
    assert isinstance(position, dict)
    return float(position["north_m"])


async def test_full_flight_by_rest(quad_api: Api) -> None:
    api = quad_api
    await api.take_control()

    arm = await api.control("arm", {"force": False})
    assert arm.status_code == 200, arm.text
    assert arm.json()["command"] == "MAV_CMD_COMPONENT_ARM_DISARM"
    assert arm.json()["result"] == "ACCEPTED"
    assert arm.json()["result_code"] == 0

    takeoff = await api.control("takeoff", {"altitude_m": 5.0})
    assert takeoff.status_code == 200, takeoff.text
    await api.wait_state(lambda s: s["position_ned"]["down_m"] < -4.0, 15.0, "climb to 4 m")

    start = await api.control(
        "offboard/start",
        {"setpoint": {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -5.0}},
    )
    assert start.status_code == 200, start.text
    state = await api.state()
    assert state["mode"] == "OFFBOARD"
    assert state["stream"]["active"] is True

    moved = await api.control(
        "setpoint", {"type": "position_ned", "north_m": 6.0, "east_m": 0.0, "down_m": -5.0}
    )
    assert moved.status_code == 200, moved.text
    assert moved.json()["message"] == "SET_POSITION_TARGET_LOCAL_NED"
    assert moved.json()["setpoint"]["north_m"] == 6.0
    await api.wait_state(lambda s: abs(_north_m(s) - 6.0) < 0.7, 10.0, "arrive 6 m north")

    velocity = await api.control(
        "setpoint", {"type": "velocity_ned", "north_m_s": -2.0, "east_m_s": 0.0, "down_m_s": 0.0}
    )
    assert velocity.status_code == 200, velocity.text
    await api.wait_state(
        lambda s: s["velocity_ned"]["north_m_s"] < -1.5, 10.0, "fly south at 2 m/s"
    )
    stats = (await api.client.get("/api/v1/vehicles/1/stream")).json()
    assert stats["active"] is True
    assert stats["sent"] > 0
    assert stats["rate_hz"] > 5.0

    home = state["home"]
    reposition = await api.control(
        "reposition",
        {
            "lat_deg": home["lat_deg"] + 10.0 / 111_320.0,
            "lon_deg": home["lon_deg"],
            "alt_rel_m": 6.0,
        },
    )
    assert reposition.status_code == 200, reposition.text
    await api.wait_state(
        lambda s: s["mode"] == "HOLD" and abs(_north_m(s) - 10.0) < 1.5, 20.0, "reposition"
    )

    rtl = await api.control("rtl")
    assert rtl.status_code == 200, rtl.text
    await api.wait_state(lambda s: s["mode"] == "RTL", 5.0, "RTL mode")
    landed = await api.wait_state(
        lambda s: s["landed_state"] == "ON_GROUND" and not s["armed"], 60.0, "land at home"
    )
    assert math.hypot(landed["position_ned"]["north_m"], landed["position_ned"]["east_m"]) < 2.0


async def test_hold_and_land_commands_fly_the_vehicle(quad_api: Api) -> None:
    api = quad_api
    await api.take_control()
    assert (await api.control("arm")).status_code == 200
    assert (await api.control("takeoff", {"altitude_m": 3.0})).status_code == 200
    await api.wait_state(lambda s: s["position_ned"]["down_m"] < -2.0, 15.0, "climb")
    hold = await api.control("hold")
    assert hold.status_code == 200, hold.text
    await api.wait_state(lambda s: s["mode"] == "HOLD", 5.0, "HOLD")
    land = await api.control("land")
    assert land.status_code == 200, land.text
    assert land.json()["command"] == "MAV_CMD_NAV_LAND"
    await api.wait_state(lambda s: s["landed_state"] == "ON_GROUND", 30.0, "touchdown")


async def test_mode_change_resolves_with_the_reported_mode(quad_api: Api) -> None:
    api = quad_api
    await api.take_control()
    response = await api.control("mode", {"mode": "POSCTL"})
    assert response.status_code == 200, response.text
    assert (await api.state())["mode"] == "POSCTL"


async def test_offboard_stop_switches_mode_and_stops_the_stream(quad_api: Api) -> None:
    api = quad_api
    await api.take_control()
    start = await api.control("offboard/start", {"setpoint": HOLD_STILL})
    assert start.status_code == 200, start.text
    stop = await api.control("offboard/stop", {"then_mode": "HOLD"})
    assert stop.status_code == 200, stop.text
    state = await api.state()
    assert state["mode"] == "HOLD"
    assert state["stream"]["active"] is False


async def test_arming_in_offboard_without_stream_switches_to_hold_first(quad_api: Api) -> None:
    api = quad_api
    await api.take_control()
    # Disarmed, PX4 accepts the switch to OFFBOARD with no stream, then would refuse to arm
    # ("No offboard signal"): the server picks Hold, where it arms, as after an RTL.
    mode = await api.client.post(
        "/api/v1/vehicles/1/mode", json={"mode": "OFFBOARD"}, headers=api.lease_headers
    )
    assert mode.status_code == 200, mode.text
    arm = await api.control("arm")
    assert arm.status_code == 200, arm.text
    assert arm.json()["command"] == "MAV_CMD_COMPONENT_ARM_DISARM"
    state = await api.wait_state(lambda s: s["armed"], 5.0, "armed")
    assert state["mode"] == "HOLD"


async def test_disarm_in_the_air_is_refused(quad_api: Api) -> None:
    api = quad_api
    await api.take_control()
    assert (await api.control("arm")).status_code == 200
    assert (await api.control("takeoff", {"altitude_m": 3.0})).status_code == 200
    await api.wait_state(lambda s: s["landed_state"] == "IN_AIR", 15.0, "in the air")
    disarm = await api.control("disarm", {"force": False})
    assert disarm.status_code == 409, disarm.text
    assert disarm.json()["result"] in ("TEMPORARILY_REJECTED", "DENIED")


async def test_vtol_transition_on_a_quad_is_refused_at_once_409(quad_api: Api) -> None:
    # PX4 sends no ack for DO_VTOL_TRANSITION on a non-VTOL: it is refused without asking.
    api = quad_api
    await api.take_control()
    response = await api.control("vtol/transition", {"to": "fixed_wing", "wait": False})
    assert response.status_code == 409, response.text
    assert response.json()["result"] == "FAILED"
    assert response.json()["result_code"] is None
    assert response.json()["reason"].startswith("not a VTOL (QUADROTOR)")
    assert response.json()["elapsed_ms"] < 100


async def test_origin_and_home_are_set_and_reported(quad_api: Api) -> None:
    api = quad_api
    await api.take_control()
    home = (await api.state())["home"]
    lat, lon = home["lat_deg"] + 0.0001, home["lon_deg"] + 0.0001
    response = await api.control("home", {"lat_deg": lat, "lon_deg": lon, "alt_amsl_m": 490.0})
    assert response.status_code == 200, response.text
    await api.wait_state(
        lambda s: abs(s["home"]["lat_deg"] - lat) < 1e-6, 10.0, "the new home reported"
    )
    here = await api.control("home")
    assert here.status_code == 200, here.text
    origin = await api.control(
        "origin", {"lat_deg": home["lat_deg"], "lon_deg": home["lon_deg"], "alt_amsl_m": 489.4}
    )
    assert origin.status_code == 200, origin.text
    assert (await api.state())["origin"] is not None


async def test_disarm_on_the_ground_is_accepted(quad_api: Api) -> None:
    api = quad_api
    await api.take_control()
    assert (await api.control("arm")).status_code == 200
    await api.wait_state(lambda s: s["armed"] is True, 5.0, "armed")
    disarm = await api.control("disarm", {"force": False})
    assert disarm.status_code == 200, disarm.text
    await api.wait_state(lambda s: s["armed"] is False, 5.0, "disarmed")
