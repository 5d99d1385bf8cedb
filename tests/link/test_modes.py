"""PX4 mode codec: names <-> (main, sub) <-> custom_mode."""

from __future__ import annotations

import pytest

from server.link.codec import modes
from server.link.codec.modes import PX4_MODE_NAMES
from skyhelm_wire import modes as wire_modes


@pytest.mark.parametrize("name", PX4_MODE_NAMES)
def test_every_mode_name_round_trips_through_custom_mode(name: str) -> None:
    custom_mode = modes.custom_mode_from_name(name)

    assert modes.name_from_custom_mode(custom_mode) == name
    assert modes.name_from_main_sub(*modes.main_sub_from_name(name)) == name


@pytest.mark.parametrize(
    ("name", "custom_mode"),
    [("OFFBOARD", 0x60000), ("POSCTL", 0x30000), ("TAKEOFF", 0x2040000),
     ("HOLD", 0x3040000), ("RTL", 0x5040000), ("LAND", 0x6040000)],
)  # fmt: skip
def test_custom_mode_matches_px4_heartbeat_values(name: str, custom_mode: int) -> None:
    assert modes.custom_mode_from_name(name) == custom_mode


def test_mode_names_cover_the_px4_modes_the_dashboard_offers() -> None:
    assert set(PX4_MODE_NAMES) >= {
        "MANUAL", "ALTCTL", "POSCTL", "POSCTL_ORBIT", "ACRO", "STABILIZED", "OFFBOARD", "HOLD",
        "TAKEOFF", "LAND", "RTL", "MISSION", "FOLLOW_TARGET", "PRECLAND", "VTOL_TAKEOFF",
        "TERMINATION",
    }  # fmt: skip
    assert len(set(map(modes.custom_mode_from_name, PX4_MODE_NAMES))) == len(PX4_MODE_NAMES)


def test_names_are_case_insensitive_and_unknown_names_raise() -> None:
    assert modes.main_sub_from_name("offboard") == (6, 0)
    with pytest.raises(modes.UnknownModeError):
        modes.main_sub_from_name("WARP")


def test_unknown_auto_sub_mode_is_named_by_its_numbers() -> None:
    assert modes.name_from_main_sub(4, 7) == "MAIN_4_SUB_7"
    assert modes.name_from_main_sub(6, 3) == "OFFBOARD"  # sub ignored outside AUTO/POSCTL


def test_set_mode_base_mode_has_custom_bit_and_armed_bit_when_armed() -> None:
    assert modes.set_mode_base_mode(armed=False) == 1
    assert modes.set_mode_base_mode(armed=True) == 129


def test_the_codec_knows_every_mode_name_the_wire_takes_and_no_other() -> None:
    assert PX4_MODE_NAMES == wire_modes.PX4_MODE_NAMES
