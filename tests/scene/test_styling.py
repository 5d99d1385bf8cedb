"""Colour by state, trails and throttling: the scene's presentation policies."""

from __future__ import annotations

import pytest

from server.scene.models import model_kind, rotor_count, rotor_positions_flu
from server.scene.styling import STATE_COLOURS, blend, rotor_colour, state_category, state_colour
from server.scene.trail import Trail


@pytest.mark.parametrize(
    ("armed", "mode", "user_mode", "status", "expected"),
    [
        (False, "HOLD", "HOLD", "STANDBY", "disarmed"),
        (False, "OFFBOARD", "OFFBOARD", "STANDBY", "disarmed"),
        (True, "HOLD", "HOLD", "ACTIVE", "armed"),
        (True, "TAKEOFF", None, "ACTIVE", "armed"),
        (True, "OFFBOARD", "OFFBOARD", "ACTIVE", "offboard"),
        (True, "POSCTL", "OFFBOARD", "ACTIVE", "failsafe"),
        (True, "OFFBOARD", "OFFBOARD", "CRITICAL", "failsafe"),
        (True, "LAND", None, "MAV_STATE_EMERGENCY", "failsafe"),
    ],
)
def test_state_category(armed: bool, mode: str, user_mode: str | None, status: str,
                        expected: str) -> None:
    got = state_category(armed=armed, mode=mode, user_mode=user_mode, system_status=status)
    assert got == expected
    colour = state_colour(armed=armed, mode=mode, user_mode=user_mode, system_status=status)
    assert colour == STATE_COLOURS[got]


def test_state_colours_are_distinct() -> None:
    assert len(set(STATE_COLOURS.values())) == len(STATE_COLOURS)


def test_rotor_colour_brightens_with_output() -> None:
    shades = [sum(rotor_colour(x / 10)) for x in range(11)]
    assert shades == sorted(shades)
    assert shades[0] < shades[-1]


def test_trail_fades_with_age_and_forgets_after_sixty_seconds() -> None:
    trail = Trail()
    for i in range(100):
        trail.add(float(i), (float(i), 0.0, 0.0))
    assert len(trail) == 61
    points, colours = trail.segments(99.0, (200, 100, 0), (0, 0, 0))
    assert points.shape == (60, 2, 3)
    assert points[0, 0, 0] == 39.0
    assert int(colours[0, 0, 0]) < int(colours[-1, 1, 0]) == 200
    assert blend((200, 100, 0), (0, 0, 0), 0.5) == (100, 50, 0)


def test_trail_skips_samples_closer_than_its_spacing() -> None:
    trail = Trail()
    assert trail.add(0.0, (0.0, 0.0, 0.0))
    assert not trail.add(0.05, (1.0, 0.0, 0.0))
    assert not trail.add(1.0, (0.0, 0.0, 0.01))
    assert trail.add(1.0, (0.0, 0.0, 1.0))


def test_model_kind_and_rotor_layout_follow_mav_type() -> None:
    assert model_kind("QUADROTOR") == "multicopter"
    assert model_kind("VTOL_FIXEDROTOR") == "vtol"
    assert model_kind("FIXED_WING") == "fixed_wing"
    assert model_kind("GROUND_ROVER") == "rover"
    assert rotor_count("HEXAROTOR") == 6
    rotors = rotor_positions_flu(4, 1.0)
    assert all(x != 0 and y != 0 for x, y in rotors)
    assert sorted((x > 0, y > 0) for x, y in rotors) == sorted(
        [(True, True), (True, False), (False, True), (False, False)])
