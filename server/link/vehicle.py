"""One vehicle on a link: its state, its commands, its setpoint stream, its parameters.

The Link creates a Vehicle on the first HEARTBEAT of a new autopilot and then feeds it
every message from that system through handle_message(); the vehicle talks back through
link.send(). Every operation returns the vehicle's own answer.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import development as mavlink

from server.link import modes
from server.link.commands import CommandInt, CommandOutcome, CommandProtocol, CommandResult
from server.link.events import EventHub, VehicleEvent
from server.link.params import ParamClient
from server.link.setpoint_checks import (
    Envelope,
    Reference,
    SetpointRejected,
    check,
    vehicle_class,
)
from server.link.setpoints import PositionNed, SentSetpoint, Setpoint, describe, encode, resolve
from server.link.state import (
    LANDED_STATE_NAMES,
    VTOL_STATE_NAMES,
    AttitudeState,
    BatteryState,
    GlobalState,
    GpsState,
    HomeState,
    OriginState,
    PositionNedState,
    StateSubscription,
    StatusText,
    StreamStats,
    SubscriptionHub,
    VehicleState,
    VelocityNedState,
)
from server.link.statustext import RecentTexts, StatusTextAssembler, severity_name
from server.link.streamer import DEFAULT_RATE_HZ, SetpointStreamer

if TYPE_CHECKING:
    from server.link.link import Link

MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_DO_SET_HOME = 179
MAV_CMD_DO_REPOSITION = 192
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MAV_CMD_DO_VTOL_TRANSITION = 3000
MAV_DO_REPOSITION_FLAGS_CHANGE_MODE = 1
MAV_FRAME_GLOBAL = 0
MAV_VTOL_STATE_TRANSITION_TO_FW = 1
MAV_VTOL_STATE_TRANSITION_TO_MC = 2
MAV_VTOL_STATE_MC = 3
MAV_VTOL_STATE_FW = 4
MAVLINK_MSG_ID_SET_GPS_GLOBAL_ORIGIN = 48
PX4_ARM_DISARM_FORCE = 21196
STATUSTEXT_KEEP = 20
NAN = math.nan

# What the dashboard needs, in Hz. CURRENT_MODE at >= 5 Hz because HEARTBEAT (1 Hz) shows
# failsafe mode changes late.
DEFAULT_TELEMETRY_RATES_HZ: Mapping[int, float] = {
    mavlink.MAVLINK_MSG_ID_CURRENT_MODE: 5.0,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: 1.0,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 20.0,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 20.0,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
    mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 5.0,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 2.0,
    mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 5.0,
}
# Sent once on connection: their values do not change often enough to stream.
ONE_SHOT_MESSAGES = (mavlink.MAVLINK_MSG_ID_HOME_POSITION, mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)

# PX4's RTL announces its phases in STATUSTEXT ("RTL: climb to ...", "RTL: land at ...")
_RTL_PHASES = (
    ("landed", "LANDED"),
    ("move to land", "MOVE_TO_LAND"),
    ("climb", "CLIMBING"),
    ("start return", "RETURNING"),
    ("return at", "RETURNING"),
    ("descend", "DESCENDING"),
    ("loiter", "LOITERING"),
    ("land", "LANDING"),
    ("completed", "COMPLETED"),
)


def _enum_name(enum: str, value: int, prefix: str) -> str:
    entry = mavlink.enums[enum].get(value)
    return entry.name.removeprefix(prefix) if entry is not None else str(value)


class Vehicle:
    """A PX4 vehicle seen on a link. Created by the Link on discovery."""

    mode_confirm_timeout_s = 3.0
    offboard_prestream_s = 1.0
    origin_retries = 3
    origin_timeout_s = 0.5

    def __init__(
        self,
        *,
        link: Link,
        sysid: int,
        compid: int,
        heartbeat: mavlink.MAVLink_heartbeat_message | None = None,
        telemetry_rates_hz: Mapping[int, float] | None = None,
        stream_rate_hz: float = DEFAULT_RATE_HZ,
    ) -> None:
        self.link = link
        self.sysid = sysid
        self.compid = compid
        self.envelope = Envelope()
        self.mav_type = heartbeat.type if heartbeat is not None else 0
        self.autopilot = heartbeat.autopilot if heartbeat is not None else 0
        self.connected = True
        self._created_s = time.monotonic()
        self._events = EventHub()
        self._hub = SubscriptionHub(self.snapshot)
        self._changed = asyncio.Event()
        self._texts = RecentTexts(time.monotonic)
        self._assembler = StatusTextAssembler(time.monotonic)
        self.commands = CommandProtocol(
            send=link.send, mav=link.mav, target_system=sysid, target_component=compid,
            own_system=link.mav.srcSystem, texts=self._texts, publish=self.publish_event,
        )  # fmt: skip
        self.params = ParamClient(
            send=link.send, mav=link.mav, target_system=sysid, target_component=compid
        )
        self._streamer = SetpointStreamer(link.send, rate_hz=stream_rate_hz)
        self._telemetry_rates_hz = (
            DEFAULT_TELEMETRY_RATES_HZ if telemetry_rates_hz is None else telemetry_rates_hz
        )
        self._telemetry_task: asyncio.Task[None] | None = None
        self._telemetry_refused: dict[str, str] = {}

        # state as last reported
        self._last_heartbeat_s = time.monotonic()
        self._base_mode = 0
        self._mode = "UNKNOWN"
        self._user_mode: str | None = None
        self._current_mode_s: float | None = None
        self._armed = False
        self._system_status = "UNINIT"
        self._landed_state = 0
        self._vtol_state = 0
        self._position: PositionNedState | None = None
        self._velocity: VelocityNedState | None = None
        self._global: GlobalState | None = None
        self._attitude: AttitudeState | None = None
        self._ground_speed_m_s: float | None = None
        self._air_speed_m_s: float | None = None
        self._climb_rate_m_s: float | None = None
        self._heading_deg: float | None = None
        self._battery: BatteryState | None = None
        self._gps: GpsState | None = None
        self._home: HomeState | None = None
        self._origin: OriginState | None = None
        self._setpoint: Setpoint | None = None
        self._target_ned: PositionNedState | None = None
        self._actuators: tuple[float, ...] = ()
        self._statustext: list[StatusText] = []
        self._rtl_phase: str | None = None
        self._offboard_engaged = False
        self._updated_s = time.monotonic()

        self._handlers: dict[str, Callable[[Any], None]] = {
            "HEARTBEAT": self._on_heartbeat,
            "CURRENT_MODE": self._on_current_mode,
            "EXTENDED_SYS_STATE": self._on_extended_sys_state,
            "LOCAL_POSITION_NED": self._on_local_position,
            "GLOBAL_POSITION_INT": self._on_global_position,
            "ATTITUDE": self._on_attitude,
            "VFR_HUD": self._on_vfr_hud,
            "SYS_STATUS": self._on_sys_status,
            "BATTERY_STATUS": self._on_battery_status,
            "GPS_RAW_INT": self._on_gps_raw,
            "HOME_POSITION": self._on_home,
            "GPS_GLOBAL_ORIGIN": self._on_origin,
            "POSITION_TARGET_LOCAL_NED": self._on_position_target,
            "SERVO_OUTPUT_RAW": self._on_servo_output,
            "ACTUATOR_OUTPUT_STATUS": self._on_actuator_output,
            "STATUSTEXT": self._on_statustext,
            "COMMAND_ACK": self._on_command_ack,
            "PARAM_VALUE": self.params.handle_param_value,
        }
        self._start_telemetry_requests()

    # -- feeding (called by the Link) ----------------------------------------------
    def handle_message(self, msg: mavlink.MAVLink_message) -> None:
        if msg.get_srcComponent() != self.compid and msg.get_type() != "STATUSTEXT":
            return
        handler = self._handlers.get(msg.get_type())
        if handler is None:
            return
        handler(msg)
        self._updated_s = time.monotonic()
        self._changed.set()
        self._hub.notify()

    def set_connected(self, connected: bool) -> None:
        if connected == self.connected:
            return
        self.connected = connected
        self.publish_event("connection", {"connected": connected})
        if connected:
            self._start_telemetry_requests()
        else:
            self.commands.fail_all()
        self._changed.set()
        self._hub.notify()

    async def close(self) -> None:
        self._streamer.stop()
        if self._telemetry_task is not None:
            self._telemetry_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._telemetry_task
        self._hub.close_all()

    # -- observing --------------------------------------------------------------------
    def snapshot(self) -> VehicleState:
        return VehicleState(
            sysid=self.sysid,
            compid=self.compid,
            mav_type=_enum_name("MAV_TYPE", self.mav_type, "MAV_TYPE_"),
            autopilot=_enum_name("MAV_AUTOPILOT", self.autopilot, "MAV_AUTOPILOT_"),
            connected=self.connected,
            last_heartbeat_age_s=time.monotonic() - self._last_heartbeat_s,
            mode=self._mode,
            user_mode=self._user_mode,
            armed=self._armed,
            system_status=self._system_status,
            landed_state=LANDED_STATE_NAMES[self._landed_state],
            vtol_state=VTOL_STATE_NAMES[self._vtol_state],
            position_ned=self._position,
            velocity_ned=self._velocity,
            global_position=self._global,
            attitude=self._attitude,
            ground_speed_m_s=self._ground_speed_m_s,
            air_speed_m_s=self._air_speed_m_s,
            climb_rate_m_s=self._climb_rate_m_s,
            heading_deg=self._heading_deg,
            battery=self._battery,
            gps=self._gps,
            home=self._home,
            origin=self._origin,
            setpoint=describe(self._setpoint) if self._setpoint is not None else None,
            target_ned=self._target_ned,
            stream=self._streamer.stats(),
            actuator_outputs=self._actuators,
            statustext=tuple(self._statustext),
            rtl_phase=self._rtl_phase,
            link=self.link.stats(),
            updated_s=self._updated_s,
            telemetry_refused=tuple(sorted(self._telemetry_refused)),
        )

    def subscribe(self) -> StateSubscription:
        return self._hub.subscribe()

    def subscribe_events(self, maxsize: int = 256) -> asyncio.Queue[VehicleEvent]:
        return self._events.subscribe(maxsize)

    def unsubscribe_events(self, queue: asyncio.Queue[VehicleEvent]) -> None:
        self._events.unsubscribe(queue)

    def publish_event(self, kind: str, data: dict[str, object]) -> None:
        self._events.publish(kind, data)

    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Wait until ``predicate()`` holds after some message; False on timeout."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while not predicate():
            remaining = deadline - loop.time()
            if remaining <= 0:
                return False
            self._changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._changed.wait(), remaining)
        return True

    # -- commands ---------------------------------------------------------------------
    async def command_long(
        self, command: int, *params: float, confirm_timeout_s: float | None = None
    ) -> CommandResult:
        return await self.commands.command_long(command, *params, timeout_s=confirm_timeout_s)

    async def arm(self, force: bool = False) -> CommandResult:
        return await self.command_long(
            MAV_CMD_COMPONENT_ARM_DISARM, 1, PX4_ARM_DISARM_FORCE if force else 0
        )

    async def disarm(self, force: bool = False) -> CommandResult:
        return await self.command_long(
            MAV_CMD_COMPONENT_ARM_DISARM, 0, PX4_ARM_DISARM_FORCE if force else 0
        )

    async def takeoff(self, altitude_rel_m: float | None = None) -> CommandResult:
        """Climb to altitude_rel_m above home (None: PX4's MIS_TAKEOFF_ALT)."""
        alt_amsl = NAN
        if altitude_rel_m is not None:
            home_alt = self._home_alt_amsl()
            if home_alt is None:
                return self._not_sent(MAV_CMD_NAV_TAKEOFF, "no home position yet")
            alt_amsl = home_alt + altitude_rel_m
        return await self.command_long(MAV_CMD_NAV_TAKEOFF, NAN, NAN, NAN, NAN, NAN, NAN, alt_amsl)

    async def land(self) -> CommandResult:
        return await self.command_long(MAV_CMD_NAV_LAND)

    async def return_to_launch(self) -> CommandResult:
        return await self.command_long(MAV_CMD_NAV_RETURN_TO_LAUNCH)

    async def hold(self) -> CommandResult:
        return await self.set_mode("HOLD")

    async def set_mode(self, mode: str) -> CommandResult:
        """DO_SET_MODE, ACCEPTED only once the vehicle reports the mode."""
        target = mode.upper()
        main, sub = modes.main_sub_from_name(target)
        started = asyncio.get_running_loop().time()
        result = await self.command_long(
            MAV_CMD_DO_SET_MODE, modes.set_mode_base_mode(self._armed), main, sub
        )
        result = replace(result, command=f"SET_MODE:{target}")
        if not result.ok:
            return result
        confirmed = await self.wait_until(lambda: self._mode == target, self.mode_confirm_timeout_s)
        elapsed_ms = (asyncio.get_running_loop().time() - started) * 1000.0
        if confirmed:
            return replace(result, elapsed_ms=elapsed_ms)
        return replace(
            result,
            outcome=CommandOutcome.NOT_CONFIRMED,
            elapsed_ms=elapsed_ms,
            reason=f"accepted, but the vehicle still reports {self._mode}",
        )

    async def reposition(
        self,
        lat_deg: float,
        lon_deg: float,
        *,
        alt_amsl_m: float | None = None,
        alt_rel_m: float | None = None,
        ground_speed_m_s: float | None = None,
        yaw_deg: float | None = None,
        loiter_radius_m: float | None = None,
    ) -> CommandResult:
        """DO_REPOSITION as COMMAND_INT (degE7 is exact; float degrees are not)."""
        if alt_amsl_m is not None and alt_rel_m is not None:
            raise ValueError("give alt_amsl_m or alt_rel_m, not both")
        alt = NAN if alt_amsl_m is None else alt_amsl_m
        if alt_rel_m is not None:
            home_alt = self._home_alt_amsl()
            if home_alt is None:
                return self._not_sent(MAV_CMD_DO_REPOSITION, "no home position yet")
            alt = home_alt + alt_rel_m
        where = CommandInt(MAV_FRAME_GLOBAL, round(lat_deg * 1e7), round(lon_deg * 1e7), alt)
        return await self.commands.command_int(
            MAV_CMD_DO_REPOSITION, where,
            -1.0 if ground_speed_m_s is None else ground_speed_m_s,
            MAV_DO_REPOSITION_FLAGS_CHANGE_MODE,
            NAN if loiter_radius_m is None else loiter_radius_m,
            NAN if yaw_deg is None else math.radians(yaw_deg),
        )  # fmt: skip

    async def vtol_transition(
        self,
        to_fixed_wing: bool,
        immediate: bool = False,
        wait: bool = True,
        timeout_s: float = 30.0,
    ) -> CommandResult:
        """PX4 acks at once; with wait, resolve when EXTENDED_SYS_STATE shows the end state."""
        target = MAV_VTOL_STATE_FW if to_fixed_wing else MAV_VTOL_STATE_MC
        started = asyncio.get_running_loop().time()
        result = await self.command_long(MAV_CMD_DO_VTOL_TRANSITION, target, 1 if immediate else 0)
        if not result.ok or not wait:
            return result
        opposite = MAV_VTOL_STATE_MC if to_fixed_wing else MAV_VTOL_STATE_FW
        in_transition = False

        def settled() -> bool:
            nonlocal in_transition
            in_transition = in_transition or self._vtol_state in (
                MAV_VTOL_STATE_TRANSITION_TO_FW,
                MAV_VTOL_STATE_TRANSITION_TO_MC,
            )
            # back where it started after a transition: PX4 aborted it (quadchute, timeout)
            return self._vtol_state == target or (in_transition and self._vtol_state == opposite)

        await self.wait_until(settled, timeout_s)
        elapsed_ms = (asyncio.get_running_loop().time() - started) * 1000.0
        if self._vtol_state == target:
            return replace(result, elapsed_ms=elapsed_ms)
        outcome = CommandOutcome.FAILED if in_transition else CommandOutcome.NOT_CONFIRMED
        return replace(result, outcome=outcome, elapsed_ms=elapsed_ms,
                       reason=f"vtol_state is {VTOL_STATE_NAMES[self._vtol_state]}"
                              f" after {elapsed_ms / 1000:.1f} s")  # fmt: skip

    async def set_gps_origin(
        self, lat_deg: float, lon_deg: float, alt_amsl_m: float
    ) -> CommandResult:
        """SET_GPS_GLOBAL_ORIGIN is a message, not a command: PX4 answers with
        GPS_GLOBAL_ORIGIN, so that echo is the confirmation."""
        lat_e7, lon_e7, alt_mm = round(lat_deg * 1e7), round(lon_deg * 1e7), round(alt_amsl_m * 1e3)
        loop = asyncio.get_running_loop()
        started = loop.time()

        def matches() -> bool:
            o = self._origin
            return (o is not None and round(o.lat_deg * 1e7) == lat_e7
                    and round(o.lon_deg * 1e7) == lon_e7
                    and abs(o.alt_amsl_m - alt_amsl_m) < 0.01)  # fmt: skip

        outcome = CommandOutcome.TIMEOUT
        for _ in range(self.origin_retries + 1):
            self.link.send(
                self.link.mav.set_gps_global_origin_encode(
                    self.sysid, lat_e7, lon_e7, alt_mm, int(time.time() * 1e6)
                )
            )
            if await self.wait_until(matches, self.origin_timeout_s):
                outcome = CommandOutcome.ACCEPTED
                break
        return CommandResult(
            "SET_GPS_GLOBAL_ORIGIN",
            MAVLINK_MSG_ID_SET_GPS_GLOBAL_ORIGIN,
            outcome,
            None,
            (loop.time() - started) * 1000.0,
        )

    async def set_home(
        self,
        lat_deg: float | None = None,
        lon_deg: float | None = None,
        alt_amsl_m: float | None = None,
    ) -> CommandResult:
        """DO_SET_HOME at the given place, or here when no place is given."""
        if lat_deg is None and lon_deg is None:
            return await self.command_long(MAV_CMD_DO_SET_HOME, 1)
        if lat_deg is None or lon_deg is None:
            raise ValueError("give both lat_deg and lon_deg, or neither")
        if alt_amsl_m is None:
            alt_amsl_m = self._global.alt_amsl_m if self._global is not None else NAN
        where = CommandInt(MAV_FRAME_GLOBAL, round(lat_deg * 1e7), round(lon_deg * 1e7), alt_amsl_m)
        return await self.commands.command_int(MAV_CMD_DO_SET_HOME, where, 0)

    def _home_alt_amsl(self) -> float | None:
        return self._home.alt_amsl_m if self._home is not None else None

    def _not_sent(self, command: int, reason: str) -> CommandResult:
        return CommandResult(
            mavlink.enums["MAV_CMD"][command].name,
            command,
            CommandOutcome.FAILED,
            None,
            0.0,
            reason,
        )

    # -- setpoints and offboard ------------------------------------------------------------
    @property
    def streamer_active(self) -> bool:
        return self._streamer.active

    @property
    def stream_rate_hz(self) -> float:
        return self._streamer.rate_hz

    @stream_rate_hz.setter
    def stream_rate_hz(self, rate_hz: float) -> None:
        self._streamer.rate_hz = rate_hz

    def stream_stats(self) -> StreamStats:
        return self._streamer.stats()

    def check_setpoint(self, sp: Setpoint) -> None:
        self._checked(sp, self.envelope)

    def _checked(self, sp: Setpoint, envelope: Envelope) -> Setpoint:
        position = self._position
        yaw = self._attitude.yaw_deg if self._attitude is not None else None
        try:
            resolved = resolve(
                sp,
                None if position is None else (position.north_m, position.east_m,
                                                position.down_m),
                yaw,
            )  # fmt: skip
        except LookupError as exc:
            raise SetpointRejected(f"cannot convert the offset: {exc}") from None
        vclass = vehicle_class(self.mav_type, VTOL_STATE_NAMES[self._vtol_state])
        check(resolved, vclass, envelope, self._reference())
        return resolved

    def _reference(self) -> Reference:
        home = self._home
        if home is None:
            return Reference()
        return Reference(
            (home.north_m, home.east_m, home.down_m), (home.lat_deg, home.lon_deg, home.alt_amsl_m)
        )

    async def set_setpoint(self, sp: Setpoint) -> SentSetpoint:
        """Check, resolve offsets, send now and keep streaming it."""
        return self._stream(self._checked(sp, self.envelope))

    def _stream(self, resolved: Setpoint) -> SentSetpoint:
        time_boot_ms = int((time.monotonic() - self._created_s) * 1000) & 0xFFFFFFFF
        msg, sent = encode(resolved, self.link.mav, self.sysid, self.compid, time_boot_ms)
        self._setpoint = resolved
        self._streamer.stream(msg)
        self._hub.notify()
        return sent

    async def hold_position_setpoint(self) -> SentSetpoint:
        """Stream "stay here": current position and yaw. Skips the envelope, since a
        vehicle already outside it must still be able to stop."""
        position = self._position
        if position is None:
            raise SetpointRejected("no local position yet")
        yaw = self._attitude.yaw_deg if self._attitude is not None else None
        hold = PositionNed(position.north_m, position.east_m, position.down_m, yaw)
        return self._stream(self._checked(hold, Envelope(None, None, None, None)))

    async def start_offboard(self, sp: Setpoint | None = None) -> CommandResult:
        """Stream a setpoint (default: hold here) for at least offboard_prestream_s,
        then switch to OFFBOARD and wait until the vehicle reports it."""
        if sp is not None:
            await self.set_setpoint(sp)
        elif not self._streamer.active:
            await self.hold_position_setpoint()
        # PX4 docs ask for > 1 s of stream first; the code needs less, so this satisfies both
        await asyncio.sleep(max(0.0, self.offboard_prestream_s - self._streamer.streaming_for_s()))
        result = await self.set_mode("OFFBOARD")
        if not result.ok and not self._offboard_engaged:
            self._stop_stream("offboard refused")
        return result

    async def stop_offboard(self, then_mode: str = "HOLD") -> CommandResult:
        """Switch to then_mode while still streaming, then stop the stream."""
        result = await self.set_mode(then_mode)
        if result.ok:
            self._stop_stream(f"left offboard for {then_mode}")
        return result

    def _stop_stream(self, why: str) -> None:
        if self._streamer.active:
            self._streamer.stop()
            self.publish_event("stream", {"active": False, "reason": why})
        self._setpoint = None
        self._offboard_engaged = False

    def _apply_stream_policy(self) -> None:
        """Keep streaming while the user's intended mode is OFFBOARD (PX4 returns to it by
        itself after a blip); stop once the user chose another mode."""
        intended = self._user_mode if self._user_mode is not None else self._mode
        if intended == "OFFBOARD":
            self._offboard_engaged = True
        elif self._offboard_engaged:
            self._stop_stream(f"mode changed to {intended}")

    # -- parameters -----------------------------------------------------------------------
    async def get_param(self, name: str) -> float | int:
        return await self.params.get(name)

    async def get_params(self, names: Sequence[str] | None = None) -> dict[str, float | int]:
        if names is None:
            return await self.params.get_all()
        return await self.params.get_many(names)

    async def set_param(self, name: str, value: float | int) -> float | int:
        return await self.params.set(name, value)

    # -- telemetry requests -----------------------------------------------------------------
    def _start_telemetry_requests(self) -> None:
        if not self._telemetry_rates_hz:
            return
        if self._telemetry_task is not None and not self._telemetry_task.done():
            self._telemetry_task.cancel()
        self._telemetry_task = asyncio.get_running_loop().create_task(
            self._request_telemetry(), name=f"telemetry-request:{self.sysid}"
        )

    async def _request_telemetry(self) -> None:
        for msg_id, rate_hz in self._telemetry_rates_hz.items():
            result = await self.command_long(MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / rate_hz)
            self._note_telemetry_answer(msg_id, result)
        for msg_id in ONE_SHOT_MESSAGES:
            self._note_telemetry_answer(
                msg_id, await self.command_long(MAV_CMD_REQUEST_MESSAGE, msg_id)
            )

    def _note_telemetry_answer(self, msg_id: int, result: CommandResult, prefix: str = "") -> None:
        msg_class = mavlink.mavlink_map.get(msg_id)
        name = prefix + (msg_class.msgname if msg_class is not None else str(msg_id))
        if result.ok:
            self._telemetry_refused.pop(name, None)
            return
        self._telemetry_refused[name] = result.outcome.value
        self.publish_event("stream", {"message": name, "outcome": result.outcome.value})

    # -- message handlers -----------------------------------------------------------------
    def _set_mode_name(self, mode: str) -> None:
        if mode != self._mode:
            old, self._mode = self._mode, mode
            self.publish_event("mode", {"mode": mode, "previous": old})
            if mode != "RTL":
                self._rtl_phase = None

    def _on_heartbeat(self, msg: mavlink.MAVLink_heartbeat_message) -> None:
        self._last_heartbeat_s = time.monotonic()
        self.mav_type = msg.type
        self.autopilot = msg.autopilot
        self._base_mode = msg.base_mode
        self._system_status = _enum_name("MAV_STATE", msg.system_status, "MAV_STATE_")
        armed = bool(msg.base_mode & modes.MAV_MODE_FLAG_SAFETY_ARMED)
        if armed != self._armed:
            self._armed = armed
            self.publish_event("armed", {"armed": armed})
        current_mode_fresh = (
            self._current_mode_s is not None and time.monotonic() - self._current_mode_s < 2.0
        )
        if msg.base_mode & modes.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and not current_mode_fresh:
            self._set_mode_name(modes.name_from_custom_mode(msg.custom_mode))
            self._apply_stream_policy()

    def _on_current_mode(self, msg: mavlink.MAVLink_current_mode_message) -> None:
        self._current_mode_s = time.monotonic()
        self._set_mode_name(modes.name_from_custom_mode(msg.custom_mode))
        if msg.intended_custom_mode:
            self._user_mode = modes.name_from_custom_mode(msg.intended_custom_mode)
        self._apply_stream_policy()

    def _on_extended_sys_state(self, msg: mavlink.MAVLink_extended_sys_state_message) -> None:
        if 0 <= msg.landed_state < len(LANDED_STATE_NAMES):
            self._landed_state = msg.landed_state
        if 0 <= msg.vtol_state < len(VTOL_STATE_NAMES) and msg.vtol_state != self._vtol_state:
            self._vtol_state = msg.vtol_state
            self.publish_event("vtol", {"vtol_state": VTOL_STATE_NAMES[msg.vtol_state]})

    def _on_local_position(self, msg: mavlink.MAVLink_local_position_ned_message) -> None:
        self._position = PositionNedState(msg.x, msg.y, msg.z)
        self._velocity = VelocityNedState(msg.vx, msg.vy, msg.vz)

    def _on_global_position(self, msg: mavlink.MAVLink_global_position_int_message) -> None:
        self._global = GlobalState(
            msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1e3, msg.relative_alt / 1e3
        )
        if msg.hdg != 0xFFFF:
            self._heading_deg = msg.hdg / 100.0

    def _on_attitude(self, msg: mavlink.MAVLink_attitude_message) -> None:
        d = math.degrees
        self._attitude = AttitudeState(
            d(msg.roll),
            d(msg.pitch),
            d(msg.yaw),
            d(msg.rollspeed),
            d(msg.pitchspeed),
            d(msg.yawspeed),
        )

    def _on_vfr_hud(self, msg: mavlink.MAVLink_vfr_hud_message) -> None:
        self._air_speed_m_s = msg.airspeed
        self._ground_speed_m_s = msg.groundspeed
        self._climb_rate_m_s = msg.climb
        self._heading_deg = float(msg.heading)

    def _on_sys_status(self, msg: mavlink.MAVLink_sys_status_message) -> None:
        self._battery = BatteryState(
            None if msg.voltage_battery == 0xFFFF else msg.voltage_battery / 1000.0,
            None if msg.current_battery < 0 else msg.current_battery / 100.0,
            None if msg.battery_remaining < 0 else float(msg.battery_remaining),
        )

    def _on_battery_status(self, msg: mavlink.MAVLink_battery_status_message) -> None:
        cells = [v for v in msg.voltages if v != 0xFFFF]
        self._battery = BatteryState(
            sum(cells) / 1000.0 if cells else None,
            None if msg.current_battery < 0 else msg.current_battery / 100.0,
            None if msg.battery_remaining < 0 else float(msg.battery_remaining),
        )

    def _on_gps_raw(self, msg: mavlink.MAVLink_gps_raw_int_message) -> None:
        self._gps = GpsState(
            _enum_name("GPS_FIX_TYPE", msg.fix_type, "GPS_FIX_TYPE_"),
            msg.satellites_visible,
            None if msg.eph == 0xFFFF else msg.eph / 100.0,
        )

    def _on_home(self, msg: mavlink.MAVLink_home_position_message) -> None:
        self._home = HomeState(
            msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3, msg.x, msg.y, msg.z
        )

    def _on_origin(self, msg: mavlink.MAVLink_gps_global_origin_message) -> None:
        self._origin = OriginState(msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3)

    def _on_position_target(self, msg: mavlink.MAVLink_position_target_local_ned_message) -> None:
        self._target_ned = PositionNedState(msg.x, msg.y, msg.z)

    def _on_servo_output(self, msg: mavlink.MAVLink_servo_output_raw_message) -> None:
        raw = [getattr(msg, f"servo{i}_raw", 0) for i in range(1, 17)]
        self._actuators = tuple(_pwm_to_unit(v) for v in raw if v)

    def _on_actuator_output(self, msg: mavlink.MAVLink_actuator_output_status_message) -> None:
        values = msg.actuator[: msg.active]
        self._actuators = tuple(
            _pwm_to_unit(v) if v > 2.0 else min(max(v, 0.0), 1.0) for v in values
        )

    def _on_command_ack(self, msg: mavlink.MAVLink_command_ack_message) -> None:
        self.commands.handle_ack(msg, msg.get_srcComponent())

    def _on_statustext(self, msg: mavlink.MAVLink_statustext_message) -> None:
        text = msg.text if isinstance(msg.text, str) else msg.text.decode("utf-8", "replace")
        for severity, whole in self._assembler.feed(
            msg.severity, text.rstrip("\0"), getattr(msg, "id", 0), getattr(msg, "chunk_seq", 0)
        ):
            self._add_statustext(severity, whole)

    def _add_statustext(self, severity: int, text: str) -> None:
        entry = StatusText(time.time(), severity_name(severity), text)
        self._statustext.append(entry)
        del self._statustext[:-STATUSTEXT_KEEP]
        self._texts.add(severity, text)
        self.publish_event("statustext", {"severity": entry.severity, "text": text})
        lowered = text.lower()
        if lowered.startswith("rtl"):
            for keyword, phase in _RTL_PHASES:
                if keyword in lowered:
                    self._rtl_phase = phase
                    break


def _pwm_to_unit(pwm: float) -> float:
    """PX4 motor PWM 1000..2000 us as 0..1."""
    return min(max((pwm - 1000.0) / 1000.0, 0.0), 1.0)
