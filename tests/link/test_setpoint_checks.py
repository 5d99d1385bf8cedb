"""Refusals of setpoints PX4 would drop, per vehicle type, and the safety envelope."""

from __future__ import annotations

import math

import pytest

from server.link.codec import setpoints as sp
from server.link.codec.setpoint_checks import (
    Envelope,
    Reference,
    SetpointRejected,
    VehicleClass,
    check,
    vehicle_class,
)

HOME = Reference((0.0, 0.0, 0.0), (47.397742, 8.545594, 489.4))


def _refusal(
    setpoint: sp.Setpoint, vclass: VehicleClass = "multicopter", envelope: Envelope | None = None
) -> SetpointRejected:
    with pytest.raises(SetpointRejected) as info:
        check(setpoint, vclass, envelope or Envelope(), HOME)
    return info.value


@pytest.mark.parametrize(
    "setpoint",
    [sp.PositionNed(1, 1, -5, 0), sp.VelocityNed(1, 0, 0, 0), sp.VelocityBody(1, 0, 0),
     sp.AccelerationNed(1, 0, 0), sp.PositionVelocityNed(1, 1, -5, 1, 0, 0, yaw_deg=0),
     sp.PositionGlobal(47.3978, 8.5456, 10, "relative"), sp.Attitude(5, 0, 0, 0.5),
     sp.BodyRates(0, 0, 10, 0.5)],
)  # fmt: skip
def test_multicopter_accepts_every_setpoint_kind(setpoint: sp.Setpoint) -> None:
    check(setpoint, "multicopter", Envelope(), HOME)


@pytest.mark.parametrize(
    ("setpoint", "vclass", "words"),
    [
        (sp.VelocityNed(10, 0, 0), "fixed_wing", "velocity"),
        (sp.VelocityBody(10, 0, 0), "fixed_wing", "velocity"),
        (sp.AccelerationNed(1, 0, 0), "fixed_wing", "acceleration"),
        (sp.AccelerationNed(1, 0, 0), "rover", "acceleration"),
        (sp.Attitude(0, 0, 0, 0.5), "rover", "attitude"),
        (sp.BodyRates(0, 0, 0, 0.5), "rover", "rates"),
        (sp.VelocityNed(1, 0, 0), "vtol_transition", "velocity"),
    ],
)  # fmt: skip
def test_setpoint_kinds_px4_ignores_for_the_vehicle_type_are_refused(
    setpoint: sp.Setpoint, vclass: VehicleClass, words: str
) -> None:
    refusal = _refusal(setpoint, vclass)

    assert words in refusal.reason
    assert refusal.field == "type"


def test_fixed_wing_and_rover_accept_what_px4_flies_for_them() -> None:
    check(sp.PositionNed(100, 0, -50, 0), "fixed_wing", Envelope(), HOME)
    check(sp.Attitude(10, 5, 0, 0.7), "fixed_wing", Envelope(), HOME)
    check(sp.VelocityNed(2, 0, 0), "rover", Envelope(), HOME)
    check(sp.PositionNed(10, 0, 0), "rover", Envelope(), HOME)


def test_vehicle_class_follows_mav_type_and_vtol_state() -> None:
    assert vehicle_class(2, "UNDEFINED") == "multicopter"
    assert vehicle_class(1, "UNDEFINED") == "fixed_wing"
    assert vehicle_class(10, "UNDEFINED") == "rover"
    assert vehicle_class(22, "MC") == "multicopter"
    assert vehicle_class(22, "FW") == "fixed_wing"
    assert vehicle_class(22, "TRANSITION_TO_FW") == "vtol_transition"


@pytest.mark.parametrize("frame", [7, 9, 5])
def test_raw_frames_px4_rejects_are_refused_with_its_reason(frame: int) -> None:
    refusal = _refusal(sp.RawLocal(frame=frame, type_mask=2552, x=1, y=1, z=-5))

    assert refusal.reason == f"coordinate frame {frame} unsupported"
    assert refusal.field == "frame"


def test_force_bit_is_refused() -> None:
    refusal = _refusal(sp.RawLocal(frame=1, type_mask=0b110000111111 | 512, afx=1.0))

    assert refusal.reason == "force not supported"


def test_raw_setpoint_with_nothing_usable_is_refused() -> None:
    refusal = _refusal(sp.RawLocal(frame=1, type_mask=0b000111111111))

    assert refusal.reason.startswith("invalid")


def test_raw_body_frame_velocity_passes_as_velocity() -> None:
    check(sp.RawLocal(frame=8, type_mask=1479, vx=1.0), "rover", Envelope(), HOME)
    assert "velocity" in _refusal(sp.RawLocal(frame=8, type_mask=1479, vx=1.0), "fixed_wing").reason


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_numbers_are_refused(bad: float) -> None:
    refusal = _refusal(sp.VelocityNed(1.0, bad, 0.0))

    assert refusal.field == "east_m_s"


def test_thrust_outside_zero_to_one_is_refused() -> None:
    assert _refusal(sp.Attitude(0, 0, 0, 1.2)).field == "thrust"


def test_numbers_outside_their_kinds_limits_are_refused_naming_the_field() -> None:
    def limit_hit(setpoint: sp.Setpoint) -> tuple[str | None, float | None]:
        refusal = _refusal(setpoint)
        assert "must be within" in refusal.reason
        return refusal.field, refusal.limit

    assert limit_hit(sp.PositionNed(0, 0, -5, yaw_deg=400)) == ("yaw_deg", 360.0)
    assert limit_hit(sp.VelocityNed(-2e3, 0, 0)) == ("north_m_s", -1e3)
    assert limit_hit(sp.RawLocal(frame=1, type_mask=2552, x=1e39)) == ("x", 1e6)


@pytest.mark.parametrize(
    ("setpoint", "field", "limit"),
    [
        (sp.PositionNed(0, 0, -130), "max_alt_rel_m", 120.0),
        (sp.PositionNed(400, 400, -10), "max_distance_m", 500.0),
        (sp.VelocityNed(10, 10, 0), "max_speed_xy_m_s", 12.0),
        (sp.VelocityBody(0, 0, 6), "max_speed_z_m_s", 5.0),
        (sp.PositionVelocityNed(1, 1, -5, 0, 0, -7), "max_speed_z_m_s", 5.0),
        (sp.PositionGlobal(47.397742, 8.545594, 489.4 + 150), "max_alt_rel_m", 120.0),
        (sp.PositionGlobal(47.397742 + 0.01, 8.545594, 20, "relative"), "max_distance_m", 500.0),
        (sp.RawLocal(frame=1, type_mask=2552, x=0, y=0, z=-121), "max_alt_rel_m", 120.0),
    ],
)  # fmt: skip
def test_envelope_refuses_with_the_limit_hit(
    setpoint: sp.Setpoint, field: str, limit: float
) -> None:
    refusal = _refusal(setpoint)

    assert (refusal.field, refusal.limit) == (field, limit)
    assert "envelope" in refusal.reason


def test_envelope_is_measured_from_home_not_from_the_origin() -> None:
    away = Reference((300.0, 0.0, -20.0), None)

    check(sp.PositionNed(700, 0, -130), "multicopter", Envelope(), away)  # 400 m, 110 m


def test_envelope_limits_set_to_none_are_off() -> None:
    check(sp.PositionNed(0, 0, -1000), "multicopter", Envelope(max_alt_rel_m=None), HOME)
