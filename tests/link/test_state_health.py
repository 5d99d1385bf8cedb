"""The state parts the instruments need: battery consumption and time left, the estimator's
health, unhealthy sensors and the age of every source message."""

from __future__ import annotations

import asyncio

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.core.state import BatteryState
from tests.link.conftest import ScriptedSession, wait_for

_EKF_GOOD = (
    mavlink.ESTIMATOR_ATTITUDE | mavlink.ESTIMATOR_VELOCITY_HORIZ
    | mavlink.ESTIMATOR_VELOCITY_VERT | mavlink.ESTIMATOR_POS_HORIZ_REL
    | mavlink.ESTIMATOR_POS_HORIZ_ABS
)  # fmt: skip
_GPS = mavlink.MAV_SYS_STATUS_SENSOR_GPS
_AHRS = mavlink.MAV_SYS_STATUS_AHRS
_GYRO = mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO


def _battery_status(consumed_mah: int, time_remaining_s: int) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_battery_status_message(
        0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 32767,
        [4050] * 4 + [65535] * 6, 1520, consumed_mah, -1, 64, time_remaining_s,
    )  # fmt: skip


def _sys_status(present: int, health: int) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_sys_status_message(
        present, present, health, 0, 16100, 1500, 63, 0, 0, 0, 0, 0, 0
    )


async def test_battery_status_gives_consumption_and_time_left_which_sys_status_keeps(
    scripted: ScriptedSession,
) -> None:
    scripted.peer.send(_battery_status(1234, 615))
    await wait_for(lambda: scripted.vehicle.snapshot().battery is not None)
    battery = scripted.vehicle.snapshot().battery
    assert battery == BatteryState(pytest.approx(16.2), 15.2, 64.0, 1234.0, 615.0)  # type: ignore[arg-type]

    scripted.peer.send(_sys_status(_GPS, _GPS))
    await wait_for(lambda: scripted.vehicle.snapshot().battery.remaining_pct == 63.0)  # type: ignore[union-attr]
    battery = scripted.vehicle.snapshot().battery
    assert battery is not None
    assert (battery.current_a, battery.consumed_mah, battery.time_remaining_s) == (
        15.0, 1234.0, 615.0,
    )  # fmt: skip


async def test_unknown_consumption_and_time_left_are_none(scripted: ScriptedSession) -> None:
    scripted.peer.send(_battery_status(-1, 0))
    await wait_for(lambda: scripted.vehicle.snapshot().battery is not None)
    battery = scripted.vehicle.snapshot().battery
    assert battery is not None
    assert (battery.consumed_mah, battery.time_remaining_s) == (None, None)


async def test_estimator_status_names_its_flags_and_health(scripted: ScriptedSession) -> None:
    scripted.peer.send(mavlink.MAVLink_estimator_status_message(
        0, _EKF_GOOD, 0.1, 0.2, 0.3, 0.4, 0.0, float("nan"), 0.3, 0.5,
    ))  # fmt: skip
    await wait_for(lambda: scripted.vehicle.snapshot().estimator is not None)
    ekf = scripted.vehicle.snapshot().estimator
    assert ekf is not None
    assert ekf.flags == (
        "ATTITUDE", "VELOCITY_HORIZ", "VELOCITY_VERT", "POS_HORIZ_REL", "POS_HORIZ_ABS",
    )  # fmt: skip
    assert ekf.healthy
    assert (ekf.pos_horiz_ratio, ekf.mag_ratio) == (pytest.approx(0.2), pytest.approx(0.4))

    glitch = _EKF_GOOD | mavlink.ESTIMATOR_GPS_GLITCH
    scripted.peer.send(mavlink.MAVLink_estimator_status_message(
        0, glitch, 0.1, 0.2, 0.3, 0.4, 0.0, 0.0, 2.0, 0.5,
    ))  # fmt: skip
    await wait_for(lambda: "GPS_GLITCH" in scripted.vehicle.snapshot().estimator.flags)  # type: ignore[union-attr]
    assert not scripted.vehicle.snapshot().estimator.healthy  # type: ignore[union-attr]

    scripted.peer.send(mavlink.MAVLink_estimator_status_message(
        0, mavlink.ESTIMATOR_ATTITUDE, 0.1, 0.2, 0.3, 0.4, 0.0, 0.0, 0.0, 0.0,
    ))  # fmt: skip
    await wait_for(lambda: scripted.vehicle.snapshot().estimator.flags == ("ATTITUDE",))  # type: ignore[union-attr]
    assert not scripted.vehicle.snapshot().estimator.healthy  # type: ignore[union-attr]


async def test_sys_status_names_the_unhealthy_sensors(scripted: ScriptedSession) -> None:
    assert scripted.vehicle.snapshot().sensors_unhealthy is None
    present = _GPS | _AHRS | _GYRO | mavlink.MAV_SYS_STATUS_PREARM_CHECK
    scripted.peer.send(_sys_status(present, _GYRO))
    await wait_for(lambda: scripted.vehicle.snapshot().sensors_unhealthy is not None)
    # the pre-arm bit is no sensor: not being ready to arm is not a failed sensor
    assert scripted.vehicle.snapshot().sensors_unhealthy == ("SENSOR_GPS", "AHRS")
    scripted.peer.send(_sys_status(present, present))
    await wait_for(lambda: scripted.vehicle.snapshot().sensors_unhealthy == ())


async def test_every_source_message_has_an_age_that_grows_until_it_comes_again(
    scripted: ScriptedSession,
) -> None:
    assert "ATTITUDE" not in scripted.vehicle.snapshot().message_ages_s
    scripted.peer.send(mavlink.MAVLink_attitude_message(0, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0))
    await wait_for(lambda: "ATTITUDE" in scripted.vehicle.snapshot().message_ages_s)
    await asyncio.sleep(0.4)
    ages = scripted.vehicle.snapshot().message_ages_s
    assert ages["ATTITUDE"] >= 0.4
    assert "GPS_RAW_INT" not in ages  # never received: no age, rather than a made-up one

    scripted.peer.send(mavlink.MAVLink_attitude_message(0, 0.2, 0.0, 0.0, 0.0, 0.0, 0.0))
    await wait_for(lambda: scripted.vehicle.snapshot().message_ages_s["ATTITUDE"] < 0.4)
