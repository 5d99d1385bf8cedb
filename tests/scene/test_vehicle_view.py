"""One vehicle's scene nodes driven by VehicleState snapshots, on a real viser server."""

from __future__ import annotations

import numpy as np
import pytest
import viser

from server.link.core.state import HomeState, PositionNedState, VehicleState
from server.scene.frames import attitude_wxyz_enu, enu_to_geodetic
from server.scene.hub import local_origin
from server.scene.styling import STATE_COLOURS, StateCategory
from server.scene.vehicle_view import VehicleView, rtl_path_enu, setpoint_point_ned

from .conftest import ORIGIN, make_state


def test_model_sits_at_the_enu_position_with_the_attitude(scene: viser.SceneApi) -> None:
    view = VehicleView(scene, 11, "QUADROTOR")
    state = make_state(position_ned=PositionNedState(10.0, 4.0, -3.0))
    view.update(state, (1.0, 2.0, 0.5), 0.0)
    np.testing.assert_allclose(view.model.root.position, (5.0, 12.0, 3.5))
    np.testing.assert_allclose(view.model.root.wxyz, attitude_wxyz_enu(0.0, 0.0, 0.0), atol=1e-5)
    assert view.position_enu == (5.0, 12.0, 3.5)
    view.remove()


def test_hull_colour_follows_armed_offboard_and_failsafe(scene: viser.SceneApi) -> None:
    view = VehicleView(scene, 12, "QUADROTOR")
    cases: list[tuple[VehicleState, StateCategory]] = [
        (make_state(), "disarmed"),
        (make_state(armed=True, system_status="ACTIVE"), "armed"),
        (make_state(armed=True, mode="OFFBOARD", user_mode="OFFBOARD"), "offboard"),
        (make_state(armed=True, mode="POSCTL", user_mode="OFFBOARD"), "failsafe"),
    ]
    for state, category in cases:
        view.update(state, (0.0, 0.0, 0.0), 0.0)
        assert tuple(view.model.hull[0].color) == STATE_COLOURS[category]
    view.remove()


def test_rotor_discs_follow_motor_outputs(scene: viser.SceneApi) -> None:
    view = VehicleView(scene, 13, "QUADROTOR")
    view.update(make_state(actuator_outputs=(0.0, 1.0, 0.0, 1.0)), (0.0, 0.0, 0.0), 0.0)
    idle, full = view.model.rotors[0].color, view.model.rotors[1].color
    assert sum(full) > sum(idle)
    view.remove()


def test_vtol_folds_lift_rotors_in_fixed_wing_flight(scene: viser.SceneApi) -> None:
    view = VehicleView(scene, 14, "VTOL_FIXEDROTOR")
    assert view.model.mc_group is not None
    view.update(make_state(vtol_state="MC"), (0.0, 0.0, 0.0), 0.0)
    assert view.model.mc_group.visible
    view.update(make_state(vtol_state="FW"), (0.0, 0.0, 0.0), 0.0)
    assert not view.model.mc_group.visible
    view.update(make_state(vtol_state="TRANSITION_TO_MC"), (0.0, 0.0, 0.0), 0.0)
    assert view.model.mc_group.visible
    view.remove()


def test_setpoint_marker_and_rtl_path_show_only_when_they_apply(scene: viser.SceneApi) -> None:
    view = VehicleView(scene, 15, "QUADROTOR")
    flying = make_state(armed=True, mode="OFFBOARD", user_mode="OFFBOARD",
                        position_ned=PositionNedState(0.0, 0.0, -5.0),
                        setpoint={"type": "PositionNed", "north_m": 3.0, "east_m": 1.0,
                                  "down_m": -6.0})
    view.update(flying, (0.0, 0.0, 0.0), 0.0)
    assert view.setpoint_marker.visible
    np.testing.assert_allclose(view.setpoint_marker.position, (1.0, 3.0, 6.0))
    assert not view.rtl_path.visible
    view.update(make_state(armed=True, mode="RTL", user_mode="RTL",
                           position_ned=PositionNedState(20.0, 0.0, -5.0)), (0.0, 0.0, 0.0), 1.0)
    assert not view.setpoint_marker.visible
    assert view.rtl_path.visible
    view.remove()


def test_setpoint_point_from_position_or_velocity() -> None:
    assert setpoint_point_ned({"north_m": 1.0, "east_m": 2.0, "down_m": -3.0}, None) == (
        1.0, 2.0, -3.0)
    ahead = setpoint_point_ned({"north_m_s": 1.0, "east_m_s": -1.0, "down_m_s": 0.5},
                               (10.0, 0.0, -5.0))
    assert ahead == pytest.approx((12.0, -2.0, -4.0))
    assert setpoint_point_ned({"roll_deg": 5.0}, (0.0, 0.0, 0.0)) is None
    assert setpoint_point_ned(None, (0.0, 0.0, 0.0)) is None


def test_rtl_path_climbs_flies_over_home_and_descends() -> None:
    path = rtl_path_enu((30.0, 40.0, 10.0), (0.0, 0.0, 0.0))
    assert path == [(30.0, 40.0, 10.0), (30.0, 40.0, 10.0), (0.0, 0.0, 10.0), (0.0, 0.0, 0.0)]


def test_local_origin_is_reported_or_worked_back_from_home() -> None:
    origin = local_origin(make_state())
    assert origin == (ORIGIN.lat_deg, ORIGIN.lon_deg, ORIGIN.alt_amsl_m)
    home_lat, home_lon, home_alt = enu_to_geodetic(30.0, 40.0, -2.0, *origin)
    from_home = make_state(origin=None, home=HomeState(home_lat, home_lon, home_alt,
                                                       40.0, 30.0, 2.0))
    worked_back = local_origin(from_home)
    assert worked_back is not None
    assert worked_back[:2] == pytest.approx((ORIGIN.lat_deg, ORIGIN.lon_deg), abs=1e-8)
    # the ENU plane and the ellipsoid part by millimetres over 50 m
    assert worked_back[2] == pytest.approx(ORIGIN.alt_amsl_m, abs=0.01)
    assert local_origin(make_state(origin=None, home=None)) is None
