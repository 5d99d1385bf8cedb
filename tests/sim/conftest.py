"""Shared helpers for the simulated vehicle's tests.

Most commander/navigator/receiver rules do not depend on flight dynamics, so they run
on `PointMassAirframe`, a kinematic stand-in that tracks trajectory setpoints, stepped
directly in sim time (no sockets, no wall clock). Messages go through a real pymavlink
encode/decode round trip so that source ids and field types are as on the wire.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import pytest
from pymavlink.dialects.v20 import development as mavlink

from sim.lib.numeric import clamp, finite_or
from sim.lib.params import ParamReader
from sim.lib.topics import (
    ControlSetpoint,
    LandingStatus,
    TrajectorySetpoint,
    VehicleStateTruth,
    VtolState,
)
from sim.mavlink.endpoint import MavlinkCodec
from sim.vehicle import PHYSICS_DT_S, READY_TIME_S, SimVehicle

GCS_SYSID = 255
GCS_COMPID = 190

MAV_TYPES = {"quad": 2, "hexa": 13, "octo": 14, "plane": 1, "vtol": 22, "rover": 10}


class PointMassAirframe:
    """Kinematic airframe: velocity follows the setpoint with a first-order lag."""

    TAU_S = 0.2
    GAIN = 1.5

    def __init__(self, name: str, params: ParamReader) -> None:
        self.name = name
        self.mav_type = MAV_TYPES[name]
        self.is_vtol = name == "vtol"
        self.truth = VehicleStateTruth()
        self.vtol_state = VtolState.MC if self.is_vtol else VtolState.UNDEFINED
        self.in_fixed_wing_flight = name == "plane"
        self.actuator_outputs = [0.0, 0.0, 0.0, 0.0]
        self.power_fraction = 0.0
        self.landing: LandingStatus | None = None  # landed when resting on the ground
        self.transitions: list[tuple[bool, bool]] = []
        self.last_setpoint: ControlSetpoint | None = None
        self._params = params

    def reset(self, position_ned_m: list[float], yaw_rad: float) -> None:
        self.truth.position_ned_m[:] = position_ned_m
        self.truth.velocity_ned_m_s[:] = [0.0, 0.0, 0.0]
        self._set_yaw(yaw_rad)
        self.truth.on_ground = position_ned_m[2] >= 0.0

    def _set_yaw(self, yaw_rad: float) -> None:
        self.truth.q_wxyz[:] = [math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2)]

    def request_transition(self, to_fixed_wing: bool, immediate: bool) -> None:
        self.transitions.append((to_fixed_wing, immediate))
        self.vtol_state = VtolState.FW if to_fixed_wing else VtolState.MC
        self.in_fixed_wing_flight = to_fixed_wing

    def _wanted_velocity(self, sp: TrajectorySetpoint) -> list[float]:
        p = self._params
        limits = [
            finite_or(sp.max_speed_xy_m_s, p.get("MPC_XY_VEL_MAX")),
            finite_or(sp.max_speed_xy_m_s, p.get("MPC_XY_VEL_MAX")),
        ]
        wanted = []
        for axis in range(3):
            target = sp.position_ned_m[axis]
            ff = finite_or(sp.velocity_ned_m_s[axis], 0.0)
            v = ff + (self.GAIN * (target - self.truth.position_ned_m[axis])
                      if math.isfinite(target) else 0.0)
            if not math.isfinite(target) and not math.isfinite(sp.velocity_ned_m_s[axis]):
                v = self.truth.velocity_ned_m_s[axis]
                acc = sp.acceleration_ned_m_s2[axis]
                v = v + (acc * PHYSICS_DT_S if math.isfinite(acc) else -v)
            if axis < 2:
                v = clamp(v, -limits[axis], limits[axis])
            else:
                up = finite_or(sp.max_speed_up_m_s, p.get("MPC_Z_VEL_MAX_UP"))
                down = finite_or(sp.max_speed_down_m_s, p.get("MPC_Z_VEL_MAX_DN"))
                v = max(-up, min(down, v))
            wanted.append(v)
        return wanted

    def step(self, dt_s: float, armed: bool, setpoint: ControlSetpoint | None) -> None:
        self.last_setpoint = setpoint
        truth = self.truth
        if not armed or setpoint is None:
            wanted = [0.0, 0.0, 9.81 if not truth.on_ground else 0.0]
            self.power_fraction = 0.0
        elif isinstance(setpoint, TrajectorySetpoint):
            wanted = self._wanted_velocity(setpoint)
            if math.isfinite(setpoint.yaw_rad):
                self._set_yaw(setpoint.yaw_rad)
            self.power_fraction = 0.3
        else:  # an attitude or rates setpoint: the point mass holds still
            wanted = [0.0, 0.0, 0.0]
            self.power_fraction = 0.3
        alpha = min(dt_s / self.TAU_S, 1.0)
        for axis in range(3):
            truth.velocity_ned_m_s[axis] += alpha * (wanted[axis] - truth.velocity_ned_m_s[axis])
            truth.position_ned_m[axis] += truth.velocity_ned_m_s[axis] * dt_s
        if truth.position_ned_m[2] >= 0.0:
            truth.position_ned_m[2] = 0.0
            truth.velocity_ned_m_s[2] = min(truth.velocity_ned_m_s[2], 0.0)
            if truth.velocity_ned_m_s[2] == 0.0 and (not armed or setpoint is None):
                truth.velocity_ned_m_s[0] = truth.velocity_ned_m_s[1] = 0.0
        truth.on_ground = truth.position_ned_m[2] >= 0.0
        truth.airspeed_m_s = math.hypot(*truth.velocity_ned_m_s[:2])
        self.actuator_outputs = [self.power_fraction] * 4


def point_mass_defaults(airframe: str) -> dict[str, float | int]:
    return {"MPC_XY_VEL_MAX": 12.0, "MPC_Z_VEL_MAX_UP": 3.0, "MPC_Z_VEL_MAX_DN": 1.5,
            "MPC_THR_HOVER": 0.5}


class RecordingLink:
    """A link that keeps what the vehicle sends (decoded again from the wire bytes)."""

    def __init__(self, name: str = "api") -> None:
        self.name = name
        self._sent: list[Any] = []
        self._frames: list[bytes] = []  # encoded, not decoded until somebody looks
        # the vehicle's own encoder, as its UDP links use it
        self._codec = MavlinkCodec(1, 1)
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True  # messages outside the dialect come as UNKNOWN_<id>

    @property
    def has_remote(self) -> bool:
        return True

    def send(self, msg: Any) -> None:
        self._frames.append(self._codec.encode(msg))

    @property
    def sent(self) -> list[Any]:
        """Every message sent so far as a peer decodes it, each frame one message (decoded
        when first asked for: most stepped flights never look)."""
        if self._frames:
            frames, self._frames = self._frames, []
            for frame in frames:
                decoded = self._parser.parse_buffer(frame)
                assert decoded is not None
                assert len(decoded) == 1
                self._sent.extend(decoded)
        return self._sent

    @sent.setter
    def sent(self, messages: list[Any]) -> None:
        self._frames = []
        self._sent = messages

    def of_type(self, type_name: str) -> list[Any]:
        return [m for m in self.sent if m.get_type() == type_name]

    def acks(self, command: int | None = None) -> list[Any]:
        return [m for m in self.of_type("COMMAND_ACK") if command is None or m.command == command]

    def texts(self) -> list[str]:
        """STATUSTEXTs, chunked ones (same non-zero id) joined again, without PX4's
        trailing tab (as a client shows them)."""
        return [text.removesuffix("\t") for text in self.raw_texts()]

    def raw_texts(self) -> list[str]:
        """STATUSTEXTs, chunked ones (same non-zero id) joined again, as sent."""
        texts: list[str] = []
        chunk_index: dict[int, int] = {}
        for m in self.of_type("STATUSTEXT"):
            if m.id and m.id in chunk_index:
                texts[chunk_index[m.id]] += m.text
                continue
            if m.id:
                chunk_index[m.id] = len(texts)
            texts.append(m.text)
        return texts

    def clear(self) -> None:
        self._frames.clear()
        self._sent.clear()


class Harness:
    """A vehicle on the point-mass airframe with two recording links, stepped in sim time."""

    def __init__(self, vehicle: SimVehicle) -> None:
        self.vehicle = vehicle
        self.api = RecordingLink("api")
        self.gcs = RecordingLink("gcs")
        vehicle.attach_link(self.api, onboard=True)
        vehicle.attach_link(self.gcs, onboard=False)
        self._gcs_codec = mavlink.MAVLink(None, srcSystem=GCS_SYSID, srcComponent=GCS_COMPID)
        self._parser = mavlink.MAVLink(None)

    @property
    def model(self) -> PointMassAirframe:
        model = self.vehicle.model
        assert isinstance(model, PointMassAirframe)
        return model

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / PHYSICS_DT_S)):
            self.vehicle.step(PHYSICS_DT_S)

    def run_until(self, condition: Callable[[], bool], timeout_s: float) -> float:
        """Step until condition holds; the sim time it took. Fails after timeout_s."""
        start = self.vehicle.now_s
        while not condition():
            if self.vehicle.now_s - start > timeout_s:
                raise AssertionError(f"condition not met within {timeout_s} s sim time")
            self.vehicle.step(PHYSICS_DT_S)
        return self.vehicle.now_s - start

    def wait_ready(self) -> None:
        self.run_until(lambda: self.vehicle.ready, READY_TIME_S + 1.0)

    def deliver(self, msg: Any, link: RecordingLink | None = None) -> None:
        """Send msg to the vehicle as a GCS would: encoded, decoded, handled."""
        data = msg.pack(self._gcs_codec)
        self._gcs_codec.seq = (self._gcs_codec.seq + 1) % 256
        decoded = self._parser.parse_buffer(data)
        assert decoded is not None
        self.vehicle.handle_message(link or self.api, decoded[0])

    def command_long(self, command: int, *params: float, target_system: int = 1,
                     target_component: int = 1, link: RecordingLink | None = None) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self.deliver(mavlink.MAVLink_command_long_message(
            target_system, target_component, command, 0, *p), link)

    def command_int(self, command: int, frame: int, params: tuple[float, float, float, float],
                    x: int, y: int, z: float) -> None:
        self.deliver(mavlink.MAVLink_command_int_message(
            1, 1, frame, command, 0, 0, *params, x, y, z))

    def set_mode(self, mode: Any) -> None:
        self.command_long(mavlink.MAV_CMD_DO_SET_MODE, 1, mode.main, mode.sub)

    def arm(self) -> None:
        self.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)

    def local_ned(self, type_mask: int, frame: int = mavlink.MAV_FRAME_LOCAL_NED,
                  position: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  velocity: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  accel: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  yaw: float = 0.0, yaw_rate: float = 0.0,
                  target_system: int = 1, target_component: int = 1) -> None:
        self.deliver(mavlink.MAVLink_set_position_target_local_ned_message(
            int(self.vehicle.now_s * 1000), target_system, target_component, frame, type_mask,
            *position, *velocity, *accel, yaw, yaw_rate))

    def last_ack(self, command: int, link: RecordingLink | None = None) -> int:
        acks = (link or self.api).acks(command)
        assert acks, f"no COMMAND_ACK for {command}"
        return int(acks[-1].result)


HarnessFactory = Callable[..., Harness]


@pytest.fixture
def make_harness() -> HarnessFactory:
    def make(airframe: str = "quad", ready: bool = True) -> Harness:
        vehicle = SimVehicle(airframe, airframe_factory=PointMassAirframe,
                             defaults_factory=point_mass_defaults)
        harness = Harness(vehicle)
        if ready:
            harness.wait_ready()
        return harness

    return make


@pytest.fixture
def harness(make_harness: Callable[..., Harness]) -> Harness:
    return make_harness()
