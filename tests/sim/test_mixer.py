"""Mixer of seed 002: geometries, decoupling, scales and desaturation priorities."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.physics.mixer import GEOMETRIES, Mixer

ALL_GEOMETRIES = sorted(GEOMETRIES)


def _sign(x: float, eps: float = 1e-9) -> int:
    return 0 if abs(x) <= eps else (1 if x > 0 else -1)


@pytest.mark.parametrize("geometry", ALL_GEOMETRIES)
def test_thrust_alone_drives_every_rotor_equally(geometry: str) -> None:
    outputs = Mixer(geometry).mix(0.0, 0.0, 0.0, 0.37)
    assert len(outputs) == len(GEOMETRIES[geometry])
    assert outputs == pytest.approx([0.37] * len(outputs), abs=1e-9)


@pytest.mark.parametrize("geometry", ALL_GEOMETRIES)
@pytest.mark.parametrize("axis", [0, 1, 2])
def test_each_axis_command_produces_only_its_own_torque(geometry: str, axis: int) -> None:
    mixer = Mixer(geometry)
    command = [0.0, 0.0, 0.0]
    command[axis] = 0.2
    outputs = mixer.mix(command[0], command[1], command[2], 0.5)
    roll, pitch, yaw, thrust = mixer.torque_and_thrust(outputs)
    achieved = [roll, pitch, yaw]
    assert achieved[axis] > 1e-3
    for other in range(3):
        if other != axis:
            assert achieved[other] == pytest.approx(0.0, abs=1e-9)
    # attitude commands redistribute thrust, they do not change the total
    assert thrust == pytest.approx(0.5 * len(GEOMETRIES[geometry]), rel=1e-9)


def test_quad_x_rows_match_px4_sih_signs() -> None:
    mixer = Mixer("4x")
    b = mixer.effectiveness
    assert [_sign(v) for v in b[0]] == [-1, 1, 1, -1]
    assert [_sign(v) for v in b[1]] == [1, -1, 1, -1]
    assert [_sign(v) for v in b[2]] == [1, 1, -1, -1]
    # a positive roll command speeds up the left rotors (1 and 2)
    out = mixer.mix(0.3, 0.0, 0.0, 0.5)
    assert [u > 0.5 for u in out] == [False, True, True, False]


def test_quad_x_roll_factor_is_seed_value() -> None:
    out = Mixer("4x").mix(0.5, 0.0, 0.0, 0.5)
    # seed 002's 4x geometry has roll factors ±0.707
    assert [abs(v - 0.5) for v in out] == pytest.approx([0.5 / math.sqrt(2.0)] * 4, abs=1e-6)


def test_roll_pitch_yaw_scales_weaken_their_axis() -> None:
    full = Mixer("4x")
    halved = Mixer("4x", roll_scale=0.5, pitch_scale=1.0, yaw_scale=0.25)
    r_full, p_full, y_full, _ = full.torque_and_thrust(full.mix(0.2, 0.2, 0.2, 0.5))
    r_half, p_same, y_quarter, _ = halved.torque_and_thrust(halved.mix(0.2, 0.2, 0.2, 0.5))
    assert r_half == pytest.approx(0.5 * r_full)
    assert p_same == pytest.approx(p_full)
    assert y_quarter == pytest.approx(0.25 * y_full)


@pytest.mark.parametrize("geometry", ALL_GEOMETRIES)
def test_full_thrust_with_roll_reduces_thrust_not_roll(geometry: str) -> None:
    mixer = Mixer(geometry)
    free_roll = mixer.torque_and_thrust(mixer.mix(0.3, 0.0, 0.0, 0.5))[0]
    outputs = mixer.mix(0.3, 0.0, 0.0, 1.0)
    roll, _, _, thrust = mixer.torque_and_thrust(outputs)
    assert max(outputs) == pytest.approx(1.0)
    assert roll == pytest.approx(free_roll)
    assert thrust < len(outputs)
    assert mixer.saturated


@pytest.mark.parametrize("geometry", ALL_GEOMETRIES)
def test_zero_thrust_with_roll_raises_thrust_to_keep_roll(geometry: str) -> None:
    mixer = Mixer(geometry)
    free_roll = mixer.torque_and_thrust(mixer.mix(0.3, 0.0, 0.0, 0.5))[0]
    outputs = mixer.mix(0.3, 0.0, 0.0, 0.0)
    assert min(outputs) == pytest.approx(0.0, abs=1e-12)
    assert mixer.torque_and_thrust(outputs)[0] == pytest.approx(free_roll)


@pytest.mark.parametrize("geometry", ALL_GEOMETRIES)
def test_yaw_is_given_up_before_roll_and_pitch(geometry: str) -> None:
    mixer = Mixer(geometry)
    free = mixer.torque_and_thrust(mixer.mix(0.3, 0.3, 0.0, 0.5))
    saturated = mixer.torque_and_thrust(mixer.mix(0.3, 0.3, 1.0, 0.5))
    full_yaw = mixer.torque_and_thrust(mixer.mix(0.0, 0.0, 1.0, 0.5))[2]
    assert mixer.saturated
    assert saturated[0] == pytest.approx(free[0])
    assert saturated[1] == pytest.approx(free[1])
    assert 0.0 < saturated[2] < full_yaw


def test_roll_and_pitch_are_scaled_together_when_they_alone_saturate() -> None:
    mixer = Mixer("4+")
    roll, pitch, yaw, _ = mixer.torque_and_thrust(mixer.mix(1.0, -0.5, 1.0, 0.5))
    assert roll > 0.0
    assert pitch < 0.0
    assert pitch / roll == pytest.approx(-0.5)
    assert yaw == pytest.approx(0.0, abs=1e-9)


def test_mixer_definition_line_of_seed_002_is_read_with_its_scales() -> None:
    mixer = Mixer.from_definition("R: 6+ 10000 5000 2500 0")
    reference = Mixer("6+", roll_scale=1.0, pitch_scale=0.5, yaw_scale=0.25)
    assert mixer.geometry == "6+"
    assert mixer.mix(0.3, 0.3, 0.3, 0.5) == pytest.approx(reference.mix(0.3, 0.3, 0.3, 0.5))
    with pytest.raises(ValueError, match="not a multirotor mixer"):
        Mixer.from_definition("M: 2")


def test_nan_commands_are_treated_as_zero() -> None:
    outputs = Mixer("6x").mix(math.nan, 0.0, math.nan, 0.4)
    assert outputs == pytest.approx([0.4] * 6)


def test_unknown_geometry_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown geometry"):
        Mixer("5x")


command = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(
    geometry=st.sampled_from(ALL_GEOMETRIES),
    roll=command,
    pitch=command,
    yaw=command,
    thrust=st.floats(min_value=0.0, max_value=1.0, allow_nan=False),
)
def test_outputs_stay_in_range_and_keep_roll_pitch_direction(
    geometry: str, roll: float, pitch: float, yaw: float, thrust: float
) -> None:
    mixer = Mixer(geometry)
    outputs = mixer.mix(roll, pitch, yaw, thrust)
    assert all(0.0 <= u <= 1.0 for u in outputs)
    achieved_roll, achieved_pitch, achieved_yaw, _ = mixer.torque_and_thrust(outputs)
    if abs(roll) > 1e-6:
        assert _sign(achieved_roll) == _sign(roll)
    if abs(pitch) > 1e-6:
        assert _sign(achieved_pitch) == _sign(pitch)
    # yaw may be given up entirely, but never reversed
    assert _sign(achieved_yaw, 1e-9) in (0, _sign(yaw, 1e-9)) or abs(yaw) <= 1e-6
