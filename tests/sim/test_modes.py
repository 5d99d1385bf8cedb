"""The PX4 mode codec: custom_mode packing, base_mode flags, names."""

from __future__ import annotations

import pytest

from sim.lib import modes
from sim.lib.modes import Px4Mode, decode_custom_mode


@pytest.mark.parametrize(
    ("mode", "custom_mode"),
    [
        (modes.OFFBOARD, 0x60000),
        (modes.POSCTL, 0x30000),
        (modes.AUTO_TAKEOFF, 0x2040000),
        (modes.AUTO_LOITER, 0x3040000),
        (modes.AUTO_RTL, 0x5040000),
        (modes.AUTO_LAND, 0x6040000),
    ],
)
def test_custom_mode_packs_main_and_sub_mode_like_px4(mode: Px4Mode, custom_mode: int) -> None:
    assert mode.custom_mode == custom_mode
    assert decode_custom_mode(custom_mode) == mode


def test_every_named_mode_round_trips_through_custom_mode() -> None:
    for mode in modes.MODE_NAMES:
        assert decode_custom_mode(mode.custom_mode) == mode


def test_decoding_drops_sub_mode_of_modes_without_sub_modes() -> None:
    assert decode_custom_mode((6 << 16) | (3 << 24)) == modes.OFFBOARD


def test_base_mode_flags_follow_mode_family_and_arming() -> None:
    assert modes.AUTO_LOITER.base_mode(armed=False) == 1 | 4 | 8 | 16
    assert modes.AUTO_LOITER.base_mode(armed=True) == 1 | 4 | 8 | 16 | 128
    assert modes.OFFBOARD.base_mode(armed=True) == 1 | 4 | 8 | 16 | 128
    assert modes.POSCTL.base_mode(armed=False) == 1 | 8 | 16 | 64
    assert modes.STABILIZED.base_mode(armed=False) == 1 | 16 | 64
    assert modes.MANUAL.base_mode(armed=False) == 1 | 64


def test_mode_names_and_standard_modes() -> None:
    assert modes.AUTO_RTL.name == "AUTO_RTL"
    assert modes.AUTO_RTL.standard_mode == modes.MavStandardMode.SAFE_RECOVERY
    assert modes.OFFBOARD.standard_mode == modes.MavStandardMode.NON_STANDARD
    assert Px4Mode(9).name.startswith("UNKNOWN")
