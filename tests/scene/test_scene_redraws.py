"""The scene changes only what a browser would see change: each change is a message to
every watching browser and a redraw there (software WebGL without a GPU: most of a core
while it redraws). And its panel says what it shows, not viser's "Connected"."""

from __future__ import annotations

import math

import viser

from server.link.core.state import AttitudeState, PositionNedState
from server.scene.frames import attitude_wxyz_enu
from server.scene.hub import SCENE_LABEL, SceneHub
from server.scene.vehicle_view import VehicleView, moved_beyond, turned_beyond

from .conftest import make_state

PIXEL_M = 0.02


def _at(north_m: float, roll_deg: float = 0.0, outputs: float = 0.5) -> object:
    return make_state(
        armed=True, mode="OFFBOARD", user_mode="OFFBOARD",
        position_ned=PositionNedState(north_m, 0.0, -5.0),
        attitude=AttitudeState(roll_deg, 0.0, 0.0, 0.0, 0.0, 0.0),
        setpoint={"north_m": 3.0, "east_m": 0.0, "down_m": -5.0},
        actuator_outputs=(outputs,) * 4,
    )


def test_a_pose_change_under_a_pixel_moves_nothing(scene: viser.SceneApi) -> None:
    view = VehicleView(scene, 21, "QUADROTOR")
    view.update(_at(0.0), (0.0, 0.0, 0.0), 0.0, PIXEL_M)  # type: ignore[arg-type]
    shown = tuple(view.model.root.position)
    wxyz = tuple(view.model.root.wxyz)
    line = view.setpoint_line._handle.points.copy()
    rotors = [tuple(r.color) for r in view.model.rotors]
    # hover jitter: 5 mm, 0.2 degree, an output on a shade's boundary
    view.update(_at(0.005, 0.2, 0.524), (0.0, 0.0, 0.0), 0.1, PIXEL_M)  # type: ignore[arg-type]
    view.update(_at(-0.005, -0.2, 0.526), (0.0, 0.0, 0.0), 0.2, PIXEL_M)  # type: ignore[arg-type]
    assert tuple(view.model.root.position) == shown
    assert tuple(view.model.root.wxyz) == wxyz
    assert (view.setpoint_line._handle.points == line).all()
    assert [tuple(r.color) for r in view.model.rotors] == rotors
    assert view.position_enu == (0.0, -0.005, 5.0)  # the state is known, only not redrawn
    # a move of more than a pixel, a turn that moves a rotor tip more than one: shown
    view.update(_at(0.05, 5.0, 0.9), (0.0, 0.0, 0.0), 0.3, PIXEL_M)  # type: ignore[arg-type]
    assert math.isclose(view.model.root.position[1], 0.05, abs_tol=1e-6)
    assert tuple(view.model.root.wxyz) != wxyz
    assert not (view.setpoint_line._handle.points == line).all()
    assert [tuple(r.color) for r in view.model.rotors] != rotors
    view.remove()


def test_what_a_pixel_spans_decides_the_move() -> None:
    assert moved_beyond(None, (0.0, 0.0, 0.0), 1.0)
    assert not moved_beyond((0.0, 0.0, 0.0), (0.009, -0.009, 0.0), 0.01)
    assert moved_beyond((0.0, 0.0, 0.0), (0.0, 0.0, 0.011), 0.01)
    level = tuple(attitude_wxyz_enu(0.0, 0.0, 0.0))
    assert not turned_beyond(level, tuple(attitude_wxyz_enu(0.5, 0.0, 0.0)), 0.02)
    assert turned_beyond(level, tuple(attitude_wxyz_enu(3.0, 0.0, 0.0)), 0.02)


async def test_the_scene_panel_says_what_it_shows_and_a_lost_link() -> None:
    hub = SceneHub()
    await hub.start()
    try:
        assert hub.panel_label == SCENE_LABEL
        assert "Connected" not in SCENE_LABEL
        hub._apply_states([make_state(sysid=1)], 0.0)
        hub._apply_states([make_state(sysid=2)], 0.0)
        assert hub.panel_label == SCENE_LABEL
        hub._apply_states([make_state(sysid=2, connected=False)], 1.0)
        assert hub.panel_label == f"{SCENE_LABEL} · link lost: vehicle 2"
        hub._apply_states([make_state(sysid=2)], 2.0)
        assert hub.panel_label == SCENE_LABEL
    finally:
        await hub.stop()
