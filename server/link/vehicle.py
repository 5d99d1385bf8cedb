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
from typing import TYPE_CHECKING

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
from server.link.setpoints import (
    PositionGlobal,
    PositionNed,
    SentSetpoint,
    Setpoint,
    describe,
    encode,
    resolve,
)
from server.link.state import (
    LANDED_STATE_NAMES,
    VTOL_STATE_NAMES,
    StateSubscription,
    StreamStats,
    SubscriptionHub,
    VehicleState,
)
from server.link.statustext import RecentTexts
from server.link.streamer import DEFAULT_RATE_HZ, SetpointStreamer
from server.link.telemetry import Telemetry, enum_name

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
ONE_SHOT_RETRIES = 30
ONE_SHOT_RETRY_INTERVAL_S = 1.0
ONE_SHOT_MESSAGES = (mavlink.MAVLINK_MSG_ID_HOME_POSITION, mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)


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
        self.connected = True
        self._created_s = time.monotonic()
        self._events = EventHub()
        self._hub = SubscriptionHub(self.snapshot)
        self._changed = asyncio.Event()
        self._texts = RecentTexts(time.monotonic)
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

        self.telemetry = Telemetry(
            heartbeat=heartbeat,
            texts=self._texts,
            publish=self.publish_event,
            on_mode=self._apply_stream_policy,
        )
        self._setpoint: Setpoint | None = None
        self._offboard_engaged = False
        self._updated_s = time.monotonic()
        self._start_telemetry_requests()

    # -- feeding (called by the Link) ----------------------------------------------
    def handle_message(self, msg: mavlink.MAVLink_message) -> None:
        kind = msg.get_type()
        if msg.get_srcComponent() != self.compid and kind != "STATUSTEXT":
            return
        if kind == "COMMAND_ACK":
            self.commands.handle_ack(msg, msg.get_srcComponent())
        elif kind == "PARAM_VALUE":
            self.params.handle_param_value(msg)
        elif not self.telemetry.handle(msg):
            return
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
    @property
    def mav_type(self) -> int:
        return self.telemetry.mav_type

    @property
    def autopilot(self) -> int:
        return self.telemetry.autopilot

    def snapshot(self) -> VehicleState:
        t = self.telemetry
        return VehicleState(
            sysid=self.sysid,
            compid=self.compid,
            mav_type=enum_name("MAV_TYPE", t.mav_type, "MAV_TYPE_"),
            autopilot=enum_name("MAV_AUTOPILOT", t.autopilot, "MAV_AUTOPILOT_"),
            connected=self.connected,
            last_heartbeat_age_s=time.monotonic() - t.last_heartbeat_s,
            mode=t.mode,
            user_mode=t.user_mode,
            armed=t.armed,
            system_status=t.system_status,
            landed_state=LANDED_STATE_NAMES[t.landed_state],
            vtol_state=VTOL_STATE_NAMES[t.vtol_state],
            position_ned=t.position,
            velocity_ned=t.velocity,
            global_position=t.global_position,
            attitude=t.attitude,
            ground_speed_m_s=t.ground_speed_m_s,
            air_speed_m_s=t.air_speed_m_s,
            climb_rate_m_s=t.climb_rate_m_s,
            heading_deg=t.heading_deg,
            battery=t.battery,
            gps=t.gps,
            home=t.home,
            origin=t.origin,
            setpoint=describe(self._setpoint) if self._setpoint is not None else None,
            target_ned=t.target_ned,
            stream=self._streamer.stats(),
            actuator_outputs=t.actuators,
            statustext=tuple(t.statustext),
            rtl_phase=t.rtl_phase,
            link=self.link.stats(),
            updated_s=self._updated_s,
            telemetry_refused=tuple(sorted(self._telemetry_refused)),
        )

    def subscribe(self, min_interval_s: float = 0.0) -> StateSubscription:
        """Latest-wins state changes; at most one per min_interval_s (see StateSubscription)."""
        return self._hub.subscribe(min_interval_s)

    @property
    def state_version(self) -> int:
        """Changes with every state change: equal versions mean an equal snapshot (apart
        from the ages and the stream figures, which move with the clock)."""
        return self._hub.version

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
            MAV_CMD_DO_SET_MODE, modes.set_mode_base_mode(self.telemetry.armed), main, sub
        )
        result = replace(result, command=f"SET_MODE:{target}")
        if not result.ok:
            return result
        confirmed = await self.wait_until(
            lambda: self.telemetry.mode == target, self.mode_confirm_timeout_s
        )
        elapsed_ms = (asyncio.get_running_loop().time() - started) * 1000.0
        if confirmed:
            return replace(result, elapsed_ms=elapsed_ms)
        return replace(
            result,
            outcome=CommandOutcome.NOT_CONFIRMED,
            elapsed_ms=elapsed_ms,
            reason=f"accepted, but the vehicle still reports {self.telemetry.mode}",
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
            in_transition = in_transition or self.telemetry.vtol_state in (
                MAV_VTOL_STATE_TRANSITION_TO_FW,
                MAV_VTOL_STATE_TRANSITION_TO_MC,
            )
            # back where it started after a transition: PX4 aborted it (quadchute, timeout)
            return self.telemetry.vtol_state == target or (
                in_transition and self.telemetry.vtol_state == opposite
            )

        await self.wait_until(settled, timeout_s)
        elapsed_ms = (asyncio.get_running_loop().time() - started) * 1000.0
        if self.telemetry.vtol_state == target:
            return replace(result, elapsed_ms=elapsed_ms)
        outcome = CommandOutcome.FAILED if in_transition else CommandOutcome.NOT_CONFIRMED
        return replace(result, outcome=outcome, elapsed_ms=elapsed_ms,
                       reason=f"vtol_state is {VTOL_STATE_NAMES[self.telemetry.vtol_state]}"
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
            o = self.telemetry.origin
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
            here = self.telemetry.global_position
            alt_amsl_m = here.alt_amsl_m if here is not None else NAN
        where = CommandInt(MAV_FRAME_GLOBAL, round(lat_deg * 1e7), round(lon_deg * 1e7), alt_amsl_m)
        return await self.commands.command_int(MAV_CMD_DO_SET_HOME, where, 0)

    def _home_alt_amsl(self) -> float | None:
        return self.telemetry.home.alt_amsl_m if self.telemetry.home is not None else None

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
        t = self.telemetry
        here = None if t.position is None else (t.position.north_m, t.position.east_m,
                                                t.position.down_m)  # fmt: skip
        try:
            resolved = resolve(sp, here, t.attitude.yaw_deg if t.attitude is not None else None)
        except LookupError as exc:
            raise SetpointRejected(f"cannot convert the offset: {exc}") from None
        if isinstance(resolved, PositionGlobal) and t.global_position is None:
            # PX4 drops global setpoints silently until it has a global position
            raise SetpointRejected("no global position yet", field="lat_deg")
        check(resolved, vehicle_class(t.mav_type, t.vtol_state_name), envelope, self._reference())
        return resolved

    def _reference(self) -> Reference:
        home = self.telemetry.home
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
        position = self.telemetry.position
        if position is None:
            raise SetpointRejected("no local position yet")
        yaw = self.telemetry.attitude.yaw_deg if self.telemetry.attitude is not None else None
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
        t = self.telemetry
        intended = t.user_mode if t.user_mode is not None else t.mode
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
        # PX4 has no home or origin until its estimator has a position, which can come
        # seconds after the first heartbeat: ask again until both are known.
        for _ in range(ONE_SHOT_RETRIES):
            missing = self._missing_one_shots()
            if not missing or not self.connected:
                return
            await asyncio.sleep(ONE_SHOT_RETRY_INTERVAL_S)
            for msg_id in missing:
                self._note_telemetry_answer(
                    msg_id, await self.command_long(MAV_CMD_REQUEST_MESSAGE, msg_id)
                )

    def _missing_one_shots(self) -> list[int]:
        missing = []
        if self.telemetry.home is None:
            missing.append(mavlink.MAVLINK_MSG_ID_HOME_POSITION)
        if self.telemetry.origin is None:
            missing.append(mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
        return missing

    def _note_telemetry_answer(self, msg_id: int, result: CommandResult, prefix: str = "") -> None:
        msg_class = mavlink.mavlink_map.get(msg_id)
        name = prefix + (msg_class.msgname if msg_class is not None else str(msg_id))
        if result.ok:
            self._telemetry_refused.pop(name, None)
            return
        self._telemetry_refused[name] = result.outcome.value
        self.publish_event("stream", {"message": name, "outcome": result.outcome.value})
