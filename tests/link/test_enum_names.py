"""Enum values are shown by their current MAVLink names."""

from server.link.plugins.mavlink_values import enum_name


def test_standard_vtol_type_is_named_fixedrotor_not_reserved() -> None:
    assert enum_name("MAV_TYPE", 22, "MAV_TYPE_") == "VTOL_FIXEDROTOR"


def test_tailsitter_quad_type_has_its_current_name() -> None:
    assert enum_name("MAV_TYPE", 20, "MAV_TYPE_") == "VTOL_TAILSITTER_QUADROTOR"


def test_unrenamed_values_come_from_the_dialect() -> None:
    assert enum_name("MAV_TYPE", 2, "MAV_TYPE_") == "QUADROTOR"


def test_unknown_value_is_shown_as_its_number() -> None:
    assert enum_name("MAV_TYPE", 250, "MAV_TYPE_") == "250"
