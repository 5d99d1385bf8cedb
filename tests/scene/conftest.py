"""Fake vehicles for the scene tests (only snapshot() is used by the scene hub) and a real
viser scene to draw into."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import sys
import time
from collections.abc import Iterator
from typing import Any

import pytest
import viser

from server.link.core.link_stats import LinkStats
from server.link.core.state import (
    AttitudeState,
    HomeState,
    OriginState,
    PositionNedState,
    StreamStats,
    VehicleState,
)

ORIGIN = OriginState(lat_deg=47.397742, lon_deg=8.545594, alt_amsl_m=488.0)


@pytest.fixture(scope="module")
def scene() -> Iterator[viser.SceneApi]:
    """A real viser server's scene, one per test module."""
    with contextlib.redirect_stdout(io.StringIO()):
        server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        yield server.scene
    finally:
        with contextlib.redirect_stdout(sys.stderr):
            server.stop()


def make_state(**changes: Any) -> VehicleState:
    state = VehicleState(
        sysid=1, compid=1, mav_type="QUADROTOR", autopilot="PX4", connected=True,
        last_heartbeat_age_s=0.1, mode="HOLD", user_mode="HOLD", armed=False, ready_to_arm=True,
        system_status="STANDBY", landed_state="ON_GROUND", vtol_state="UNDEFINED",
        position_ned=PositionNedState(0.0, 0.0, 0.0), velocity_ned=None, global_position=None,
        attitude=AttitudeState(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), ground_speed_m_s=0.0,
        air_speed_m_s=None, climb_rate_m_s=0.0, heading_deg=0.0, battery=None, gps=None,
        home=HomeState(ORIGIN.lat_deg, ORIGIN.lon_deg, ORIGIN.alt_amsl_m, 0.0, 0.0, 0.0),
        origin=ORIGIN, setpoint=None, target_ned=None, stream=StreamStats(),
        actuator_outputs=(0.0, 0.0, 0.0, 0.0), statustext=(), rtl_phase=None,
        link=LinkStats("udpin:127.0.0.1:0", True, 0, 0, 0, 0, 0, 0, 0.1, 0),
        updated_s=time.monotonic(),
    )
    return dataclasses.replace(state, **changes)


class FakeVehicle:
    """A vehicle circling home whose state changes on every snapshot."""

    def __init__(self, sysid: int = 1, mav_type: str = "QUADROTOR") -> None:
        self.sysid = sysid
        self.mav_type = mav_type
        self.snapshots = 0
        self.overrides: dict[str, Any] = {}

    def snapshot(self) -> VehicleState:
        self.snapshots += 1
        t = time.monotonic()
        return make_state(
            sysid=self.sysid, mav_type=self.mav_type, armed=True, mode="OFFBOARD",
            user_mode="OFFBOARD", system_status="ACTIVE", landed_state="IN_AIR",
            position_ned=PositionNedState(3.0 * self.sysid, 0.01 * self.snapshots, -5.0),
            updated_s=t, actuator_outputs=(0.5, 0.6, 0.5, 0.6),
            setpoint={"type": "position_ned", "north_m": 3.0, "east_m": 2.0, "down_m": -6.0},
            **self.overrides,
        )
