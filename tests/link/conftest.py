"""Shared fixtures for the vehicle side of the link: a scripted PX4 peer on UDP and,
for integration tests, the simulated vehicle with a Link and its Vehicle."""

from __future__ import annotations

import asyncio
import contextlib
import functools
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.commands import CommandResult
from server.link.core.events import VehicleEvent
from server.link.link import Link
from server.link.vehicle import Vehicle
from tests.waiting import wait_for

HEARTBEAT_PERIOD_S = 0.5


async def arm_as_sent(vehicle: Vehicle) -> CommandResult:
    """MAV_CMD_COMPONENT_ARM_DISARM as it is, without arm()'s choice of a mode to arm in:
    what the vehicle itself answers in the mode it is in."""
    return await vehicle.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, 0)


def drain(queue: asyncio.Queue[VehicleEvent]) -> list[VehicleEvent]:
    """Everything in an event queue right now."""
    items = []
    while not queue.empty():
        items.append(queue.get_nowait())
    return items


class ScriptedPeer(asyncio.DatagramProtocol):
    """A scripted PX4 autopilot on UDP: sends what the test says, records what arrives.

    ``on_command`` (if set) is called for every COMMAND_LONG / COMMAND_INT received.
    """

    def __init__(self) -> None:
        self.endpoint: asyncio.DatagramTransport | None = None
        self.decoder = mavlink.MAVLink(None)
        self.received: list[tuple[float, mavlink.MAVLink_message]] = []
        self.on_command: Callable[[mavlink.MAVLink_message], None] | None = None
        self.on_message: Callable[[mavlink.MAVLink_message], None] | None = None
        self.link_address: tuple[str, int] | None = None
        self.mav_type = mavlink.MAV_TYPE_QUADROTOR
        self.base_mode = 1
        self.custom_mode = 0x3040000  # HOLD
        # every frame sent or scheduled so far, so a test can wait until the link has them
        self.frames_promised = 0
        self._seq: dict[tuple[int, int], int] = {}
        self._arm_asked: bool | None = None  # the last ARM_DISARM's arm (True) or disarm

    def datagram_received(self, data: bytes, addr: Any) -> None:
        for msg in self.decoder.parse_buffer(data) or []:
            self.received.append((time.monotonic(), msg))
            if (msg.get_type() == "COMMAND_LONG"
                    and msg.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM):  # fmt: skip
                self._arm_asked = msg.param1 == 1
            if msg.get_type() in ("COMMAND_LONG", "COMMAND_INT") and self.on_command:
                self.on_command(msg)
            elif self.on_message is not None:
                self.on_message(msg)

    def send(self, msg: mavlink.MAVLink_message, *, sysid: int = 1, compid: int = 1) -> None:
        self.frames_promised += 1
        self._write(msg, sysid=sysid, compid=compid)

    def send_later(self, delay_s: float, msg: mavlink.MAVLink_message, **ids: int) -> None:
        self.frames_promised += 1
        asyncio.get_running_loop().call_later(delay_s, functools.partial(self._write, msg, **ids))

    def _write(self, msg: mavlink.MAVLink_message, *, sysid: int = 1, compid: int = 1) -> None:
        mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        mav.seq = self._seq.get((sysid, compid), 0)
        self._seq[(sysid, compid)] = (mav.seq + 1) % 256
        assert self.endpoint is not None
        assert self.link_address is not None
        self.endpoint.sendto(bytes(msg.pack(mav)), self.link_address)

    def heartbeat(self, *, sysid: int = 1) -> None:
        self.send(mavlink.MAVLink_heartbeat_message(
            self.mav_type, mavlink.MAV_AUTOPILOT_PX4, self.base_mode, self.custom_mode,
            mavlink.MAV_STATE_STANDBY, 3), sysid=sysid)  # fmt: skip

    def ack(
        self,
        command: int,
        result: int,
        *,
        delay_s: float = 0.0,
        progress: int = 0,
        sysid: int = 1,
        compid: int = 1,
        target_system: int = 255,
    ) -> None:
        msg = mavlink.MAVLink_command_ack_message(command, result, progress, 0, target_system, 190)
        self.send_later(delay_s, msg, sysid=sysid, compid=compid)
        if (command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM
                and result == mavlink.MAV_RESULT_ACCEPTED and self._arm_asked is not None):
            # as PX4: armed (disarmed) when it acks, and its next HEARTBEAT says so
            asyncio.get_running_loop().call_later(
                delay_s, self._report_armed, self._arm_asked, sysid
            )  # fmt: skip

    def _report_armed(self, armed: bool, sysid: int) -> None:
        armed_flag = mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        self.base_mode = self.base_mode | armed_flag if armed else self.base_mode & ~armed_flag
        self.heartbeat(sysid=sysid)

    def accept_commands(self, *, mode_report_delay_s: float = 0.0) -> None:
        """Answer every command ACCEPTED; DO_SET_MODE also changes the reported mode (in
        HEARTBEAT and CURRENT_MODE) after ``mode_report_delay_s``."""

        def answer(msg: mavlink.MAVLink_message) -> None:
            self.ack(msg.command, mavlink.MAV_RESULT_ACCEPTED)
            if msg.command == mavlink.MAV_CMD_DO_SET_MODE:
                custom_mode = int(msg.param2) << 16 | int(msg.param3) << 24
                asyncio.get_running_loop().call_later(
                    mode_report_delay_s, self.report_mode, custom_mode, custom_mode
                )

        self.on_command = answer

    def report_mode(self, custom_mode: int, intended_custom_mode: int) -> None:
        self.custom_mode = custom_mode
        self.send(mavlink.MAVLink_current_mode_message(0, custom_mode, intended_custom_mode))
        self.heartbeat()

    def messages(self, msg_type: str) -> list[mavlink.MAVLink_message]:
        return [m for _, m in self.received if m.get_type() == msg_type]

    def commands_at(self, command: int) -> list[tuple[float, mavlink.MAVLink_message]]:
        """Commands with this id as (arrival time, message)."""
        return [
            (t, m)
            for t, m in self.received
            if m.get_type() in ("COMMAND_LONG", "COMMAND_INT") and m.command == command
        ]

    def commands(self, command: int) -> list[mavlink.MAVLink_message]:
        return [
            m
            for _, m in self.received
            if m.get_type() in ("COMMAND_LONG", "COMMAND_INT") and m.command == command
        ]


class ScriptedSession:
    def __init__(self, peer: ScriptedPeer, link: Link, vehicle: Vehicle) -> None:
        self.peer = peer
        self.link = link
        self.vehicle = vehicle

    async def vehicle_heard_all(self, timeout_s: float = 2.0) -> None:
        """Until the link has taken in every frame the peer has sent or scheduled so far,
        and so the vehicle has handled them (127.0.0.1 UDP keeps their order)."""
        promised = self.peer.frames_promised
        await wait_for(
            lambda: self.link.stats().frames_in >= promised, timeout_s, "the peer's frames in"
        )

    async def peer_heard_all(self, timeout_s: float = 2.0) -> None:
        """Until the peer has every frame the link has sent so far."""
        sent = self.link.stats().frames_out
        await wait_for(lambda: len(self.peer.received) >= sent, timeout_s, "the link's frames")


def fast_vehicle(**kwargs: Any) -> Callable[..., Vehicle]:
    """A Vehicle factory with short protocol timeouts, so timeout cases run quickly."""

    def factory(**link_kwargs: Any) -> Vehicle:
        vehicle = Vehicle(**link_kwargs, **kwargs)
        vehicle.commands.timeout_s = 0.1
        vehicle.commands.reason_wait_s = 0.05
        vehicle.params.timeout_s = 0.1
        vehicle.params.list_quiet_s = 0.1
        vehicle.mode_confirm_timeout_s = 0.5
        vehicle.origin_timeout_s = 0.1
        return vehicle

    return factory


async def _keep_beating(peer: ScriptedPeer) -> None:
    while True:
        peer.heartbeat()
        # not a wait: PX4's own heartbeat period, which the link's connection timeout expects
        await asyncio.sleep(HEARTBEAT_PERIOD_S)


@pytest.fixture
async def scripted() -> AsyncIterator[ScriptedSession]:
    """A Link with a Vehicle discovered from a scripted peer (no telemetry requests)."""
    async with open_scripted(telemetry_rates_hz={}) as session:
        yield session


@contextlib.asynccontextmanager
async def open_scripted(**vehicle_kwargs: Any) -> AsyncIterator[ScriptedSession]:
    loop = asyncio.get_running_loop()
    peer = ScriptedPeer()
    peer.endpoint, _ = await loop.create_datagram_endpoint(
        lambda: peer, local_addr=("127.0.0.1", 0)
    )
    link = await Link.open(
        "udpin:127.0.0.1:0", vehicle_factory=fast_vehicle(**vehicle_kwargs), log_dir=None
    )
    assert link.local_address is not None
    peer.link_address = ("127.0.0.1", link.local_address[1])
    beat = loop.create_task(_keep_beating(peer))
    try:
        await wait_for(lambda: 1 in link.vehicles, 3.0, "discovery")
        vehicle = link.vehicles[1]
        assert isinstance(vehicle, Vehicle)
        yield ScriptedSession(peer, link, vehicle)
    finally:
        beat.cancel()
        await link.close()
        peer.endpoint.close()


class SimSession:
    def __init__(self, sim: Any, link: Link, vehicle: Vehicle) -> None:
        self.sim = sim
        self.link = link
        self.vehicle = vehicle

    @property
    def truth_ned_m(self) -> tuple[float, float, float]:
        """Where the simulated vehicle really is (test introspection only)."""
        x, y, z = self.sim.instances[0].vehicle.truth.position_ned_m
        return float(x), float(y), float(z)


@contextlib.asynccontextmanager
async def open_sim(
    airframe: str = "quad", speed: float = 5.0, ready_timeout_s: float = 10.0,
    position: bool = True,
) -> AsyncIterator[SimSession]:
    """The simulated vehicle on ephemeral ports, a Link to its API port, the Vehicle on it,
    once it has a position and a home (PX4 is ready to take off then; ``position=False``:
    once it has a home, as PX4 has from its first HEARTBEAT on)."""
    from sim.process.runner import SimCluster

    async with SimCluster(airframe=airframe, count=1, speed=speed) as sim:
        url = f"udpout:127.0.0.1:{sim.instances[0].api_local_port}"
        link = await Link.open(url, log_dir=None)
        try:
            await wait_for(lambda: 1 in link.vehicles, ready_timeout_s, "discovery")
            vehicle = link.vehicles[1]
            assert isinstance(vehicle, Vehicle)
            await wait_for(lambda: _ready(vehicle, position), ready_timeout_s,
                           "home and position" if position else "home")
            yield SimSession(sim, link, vehicle)
        finally:
            await link.close()


def _ready(vehicle: Vehicle, position: bool = True) -> bool:
    state = vehicle.snapshot()
    return state.home is not None and (state.position_ned is not None or not position)
