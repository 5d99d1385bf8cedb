"""Intents by REST and on the control socket against the simulated quad: brake, velocity,
offset and go-to, their answers, the envelope's 422s and the live velocity's deadman."""

from __future__ import annotations

import json
import math
from typing import Any

import httpx
import pymap3d
import pytest
from websockets.asyncio.client import connect

from tests.api.conftest import OBSERVER, PILOT, Api, api_for, auth, sim_cluster
from tests.api.test_ws import receive, receive_until
from tests.serving import uvicorn_serving
from tests.waiting import holds_for

INTENTS = "/api/v1/vehicles/1/intents"


def _speed_m_s(state: dict[str, Any]) -> float:
    v = state["velocity_ned"]
    return math.hypot(v["north_m_s"], v["east_m_s"], v["down_m_s"])


def _ground_distance_m(state: dict[str, Any], lat_deg: float, lon_deg: float) -> float:
    here = state["global"]
    north_m, east_m, _ = pymap3d.geodetic2ned(
        lat_deg, lon_deg, 0.0, here["lat_deg"], here["lon_deg"], 0.0
    )
    return math.hypot(north_m, east_m)


async def _intent(api: Api, name: str, body: Any = None) -> httpx.Response:
    if name == "velocity":
        return await api.client.put(f"{INTENTS}/velocity", json=body, headers=api.lease_headers)
    return await api.client.post(f"{INTENTS}/{name}", json=body, headers=api.lease_headers)


async def _hover_in_offboard(api: Api) -> dict[str, Any]:
    await api.take_control()
    assert (await api.control("arm")).status_code == 200
    assert (await api.control("takeoff", {"altitude_m": 5.0})).status_code == 200
    await api.wait_state(lambda s: s["global"]["alt_rel_m"] > 4.4, 15.0, "climb to 5 m")
    assert (await api.control("offboard/start")).status_code == 200
    return await api.state()


async def test_intents_fly_by_rest(quad_api: Api) -> None:
    api = quad_api
    state = await _hover_in_offboard(api)

    fly = await _intent(api, "velocity", {"forward_m_s": 3.0, "live": False})
    assert fly.status_code == 200, fly.text
    assert fly.json()["via"] == "setpoint"
    assert fly.json()["setpoint"]["setpoint"]["type"] == "velocity_body"
    assert fly.json()["live"] is False
    await api.wait_state(lambda s: _speed_m_s(s) > 2.5, 10.0, "3 m/s forward")

    brake = await _intent(api, "brake")
    assert brake.status_code == 200, brake.text
    assert brake.json()["setpoint"]["setpoint"]["type"] == "velocity_ned"
    await api.wait_state(
        lambda s: s["setpoint"]["type"] == "position_ned" and _speed_m_s(s) < 0.5, 15.0, "held"
    )

    here = (await api.state())["global"]
    lat_deg, lon_deg, _ = pymap3d.ned2geodetic(
        6.0, 4.0, 0.0, here["lat_deg"], here["lon_deg"], here["alt_amsl_m"]
    )
    moved = await _intent(api, "offset", {"north_m": 6.0, "east_m": 4.0})
    assert moved.status_code == 200, moved.text
    assert moved.json()["via"] == "setpoint"
    target = moved.json()["target"]
    assert (target["lat_deg"], target["lon_deg"]) == pytest.approx((lat_deg, lon_deg), abs=1e-9)
    await api.wait_state(lambda s: _ground_distance_m(s, lat_deg, lon_deg) < 0.6, 15.0, "offset")

    home = state["home"]
    back = await _intent(
        api, "goto", {"lat_deg": home["lat_deg"], "lon_deg": home["lon_deg"], "alt_rel_m": 6.0}
    )
    assert back.status_code == 200, back.text
    assert back.json()["setpoint"]["setpoint"]["type"] == "position_global"
    await api.wait_state(
        lambda s: (
            _ground_distance_m(s, home["lat_deg"], home["lon_deg"]) < 0.6
            and abs(s["global"]["alt_rel_m"] - 6.0) < 0.6
        ),
        15.0,
        "back over home",
    )

    assert (await api.control("offboard/stop", {"then_mode": "HOLD"})).status_code == 200
    away = await _intent(api, "goto", {"lat_deg": lat_deg, "lon_deg": lon_deg})
    assert away.status_code == 200, away.text
    assert away.json()["via"] == "reposition"
    assert away.json()["command"]["command"] == "MAV_CMD_DO_REPOSITION"
    assert away.json()["command"]["result"] == "ACCEPTED"
    await api.wait_state(
        lambda s: s["mode"] == "HOLD" and _ground_distance_m(s, lat_deg, lon_deg) < 1.0,
        20.0,
        "repositioned",
    )

    stop = await _intent(api, "brake")
    assert stop.status_code == 200, stop.text
    assert stop.json()["via"] == "hold_mode"


async def test_moves_outside_the_envelope_and_bad_bodies_are_422(quad_api: Api) -> None:
    api = quad_api
    await api.take_control()
    home = (await api.state())["home"]
    far_lat, far_lon, _ = pymap3d.ned2geodetic(
        510.0, 0.0, 0.0, home["lat_deg"], home["lon_deg"], home["alt_amsl_m"]
    )
    refusals: list[tuple[str, Any, str, float, str]] = [
        ("goto", {"lat_deg": far_lat, "lon_deg": far_lon}, "lat_deg", 500.0, "max_distance_m"),
        ("offset", {"north_m": 600.0}, "north_m", 500.0, "max_distance_m"),
        ("offset", {"up_m": 130.0}, "up_m", 120.0, "max_alt_rel_m"),
        ("velocity", {"north_m_s": 13.0, "frame": "ned"}, "max_speed_xy_m_s", 12.0, "12"),
    ]
    for name, body, field, limit, named in refusals:
        response = await _intent(api, name, body)
        assert response.status_code == 422, (name, response.text)
        detail = response.json()["detail"]
        assert (detail["field"], detail["limit"]) == (field, limit), name
        assert named in detail["reason"], name

    far = await api.control("reposition", {"lat_deg": far_lat, "lon_deg": far_lon})
    assert far.status_code == 422
    assert far.json()["detail"]["field"] == "lat_deg"
    high = await api.control(
        "reposition",
        {"lat_deg": home["lat_deg"], "lon_deg": home["lon_deg"],
         "alt_amsl_m": home["alt_amsl_m"] + 150.0},
    )  # fmt: skip
    assert high.status_code == 422
    assert high.json()["detail"]["field"] == "alt_amsl_m"
    assert "max_alt_rel_m 120" in high.json()["detail"]["reason"]

    bad = [
        ("velocity", {"frame": "body", "north_m_s": 1.0}),
        ("velocity", {"hold_altitude": True, "up_m_s": 1.0}),
        ("goto", {"lat_deg": 91.0, "lon_deg": 0.0}),
        ("offset", {"north_m": 1.0, "sideways_m": 2.0}),
    ]
    for name, body in bad:
        response = await _intent(api, name, body)
        assert response.status_code == 422, (name, body, response.text)
    not_a_number = await api.client.post(
        f"{INTENTS}/offset",
        content=b'{"north_m": NaN}',
        headers={**api.lease_headers, "Content-Type": "application/json"},
    )
    assert not_a_number.status_code == 422
    assert "north_m" in json.dumps(not_a_number.json()["detail"])
    assert (await api.state())["stream"]["active"] is False  # nothing was sent

    observer = await api.client.post(f"{INTENTS}/brake", headers=auth(OBSERVER))
    assert observer.status_code == 403
    no_lease = await api.client.post(f"{INTENTS}/brake")
    assert no_lease.status_code == 423


async def test_live_velocity_brakes_and_holds_when_updates_stop() -> None:
    async with sim_cluster("quad") as sim, api_for(sim, deadman_timeout_s=0.5) as api:
        await api.wait_ready()
        await _hover_in_offboard(api)

        steady = await _intent(api, "velocity", {"forward_m_s": 1.0, "live": False})
        assert steady.json()["live"] is False
        # a velocity that is not live is never cancelled by waiting past the deadman timeout
        vehicle = api.app.state.api.registry.get(1)
        await holds_for(
            lambda: getattr(vehicle.offboard.setpoint, "kind", None) == "velocity_body",
            0.8,
            "the velocity that is not live",
        )

        live = await _intent(api, "velocity", {"forward_m_s": 2.0})
        assert live.status_code == 200, live.text
        assert live.json()["live"] is True
        await api.wait_state(
            lambda s: s["setpoint"]["type"] == "position_ned" and _speed_m_s(s) < 0.5,
            15.0,
            "braked and held after the live input stopped",
        )


async def test_intents_on_the_control_socket() -> None:
    async with sim_cluster("quad") as sim, api_for(sim) as api:
        await api.wait_ready()
        home = (await api.state())["home"]
        async with uvicorn_serving(api.app) as host:
            url = f"ws://{host}/api/v1/ws/control?token={PILOT}&vehicle=1"
            async with connect(url) as ws:
                assert (await receive(ws))["type"] == "lease"
                await ws.send(json.dumps({"type": "command", "id": 1, "name": "goto",
                                          "args": {"lat_deg": home["lat_deg"] + 0.01,
                                                   "lon_deg": home["lon_deg"]}}))  # fmt: skip
                refused = await receive_until(ws, {"id": 1})
                assert refused["status"] == 422
                assert refused["body"]["detail"]["field"] == "lat_deg"
                assert "max_distance_m" in refused["body"]["detail"]["reason"]

                await ws.send(json.dumps({"type": "command", "id": 2, "name": "brake"}))
                braked = await receive_until(ws, {"id": 2})
                assert braked["body"]["intent"] == "brake"
                assert braked["body"]["via"] == "hold_mode"

                # a live velocity on the socket: the deadman brakes it when updates stop
                await ws.send(json.dumps({"type": "command", "id": 3, "name": "velocity",
                                          "args": {"forward_m_s": 0.5}}))  # fmt: skip
                flying = await receive_until(ws, {"id": 3})
                assert flying["status"] == 200, flying
                assert flying["body"]["live"] is True
                assert flying["body"]["setpoint"]["setpoint"]["type"] == "velocity_body"
                await api.wait_state(
                    lambda s: (s["setpoint"] or {}).get("type") == "position_ned",
                    10.0,
                    "braked and held",
                    renew=False,
                )
