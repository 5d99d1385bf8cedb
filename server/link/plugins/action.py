"""Action: what a vehicle is told to do (arm, take off, land, return, hold, modes,
reposition, VTOL transitions, home and GPS origin). Every answer is the vehicle's own,
through the core's requester; where PX4 acks before it acts, the reported state confirms.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math
import time
from collections.abc import Callable

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec import modes
from server.link.codec.aio import cancel_and_wait
from server.link.codec.commands import CommandInt, CommandOutcome, CommandResult, not_sent
from server.link.codec.envelope import Envelope, check_reposition, check_takeoff_altitude
from server.link.core.requests import Confirmation
from server.link.core.state import VTOL_STATE_NAMES
from server.link.core.vehicle_core import VehicleCore
from server.link.plugins.arming_modes import mode_to_arm_in
from server.link.plugins.mavlink_values import enum_name
from server.link.plugins.telemetry import Telemetry

log = logging.getLogger(__name__)

MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_DO_SET_HOME = 179
MAV_CMD_DO_REPOSITION = 192
MAV_CMD_COMPONENT_ARM_DISARM = 400
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
# MAV_TYPE_VTOL_*: the vehicle types that can take a DO_VTOL_TRANSITION
_VTOL_TYPES = frozenset(
    value for value, entry in mavlink.enums["MAV_TYPE"].items()
    if entry.name.startswith("MAV_TYPE_VTOL")
)  # fmt: skip
# PX4 reports the armed state in its 1 Hz HEARTBEAT: an arm accepted less than this long ago
# may not show in the reports yet
ARMED_REPORT_PERIOD_S = 1.5
_TAKING_OFF_MODES = frozenset({"TAKEOFF", "VTOL_TAKEOFF"})
_IN_AIR_STATES = frozenset({2, 3})  # MAV_LANDED_STATE_IN_AIR, MAV_LANDED_STATE_TAKEOFF


def _deg_e7(deg: float) -> int:
    return round(deg * 1e7)


def _not_streaming() -> bool:
    return False


class Action:
    """Commands and mode changes for one vehicle."""

    mode_confirm_timeout_s = 3.0
    # PX4 reports arming in HEARTBEAT, once a second: asked for one at once, it comes in
    # milliseconds; when that request or its answer is lost (a lossy radio), the periodic
    # ones are awaited as long as a mode change's
    arm_confirm_timeout_s = 3.0
    origin_timeout_s = 0.5  # per try of SET_GPS_GLOBAL_ORIGIN

    def __init__(self, core: VehicleCore, telemetry: Telemetry) -> None:
        self._core = core
        self._telemetry = telemetry
        # the operator's limits: take-off and reposition here, setpoints in Offboard
        self.envelope = Envelope()
        # when this client's own arm / disarm was last accepted, on the loop's clock
        self._arm_accepted_s: float | None = None
        self._disarm_accepted_s: float | None = None
        # whether this server streams offboard setpoints now (the vehicle wires its streamer)
        self.offboard_streaming: Callable[[], bool] = _not_streaming

    async def command_long(
        self, command: int, *params: float, confirm_timeout_s: float | None = None
    ) -> CommandResult:
        return await self._core.requests.command_long(command, *params, timeout_s=confirm_timeout_s)

    async def arm(self, force: bool = False) -> CommandResult:
        """Arm; on the ground in a mode PX4 will not arm in for want of something only
        the pilot's choice gives (arming_modes), switch to one it arms in first."""
        if not self._telemetry.armed:
            switched = await self._into_arming_mode()
            if switched is not None and not switched.ok:
                return switched
        return await self._arm_disarm(True, force)

    async def _into_arming_mode(self) -> CommandResult | None:
        target = mode_to_arm_in(self._telemetry.mode, self.offboard_streaming())
        return await self.set_mode(target) if target is not None else None

    async def disarm(self, force: bool = False) -> CommandResult:
        return await self._arm_disarm(False, force)

    async def _arm_disarm(self, arm: bool, force: bool) -> CommandResult:
        result = await self.command_long(
            MAV_CMD_COMPONENT_ARM_DISARM, 1 if arm else 0, PX4_ARM_DISARM_FORCE if force else 0
        )
        if result.ok and self._telemetry.armed != arm:
            result = await self._reported_armed(arm, result)
        if result.ok and arm:
            self._arm_accepted_s = self._core.now()
        elif result.ok:
            self._disarm_accepted_s = self._core.now()
        return result

    async def _reported_armed(self, arm: bool, accepted: CommandResult) -> CommandResult:
        """ACCEPTED once the vehicle reports it armed (disarmed), so the state a client reads
        after the answer says so; NOT_CONFIRMED when it never does."""
        started_s = self._core.now()
        # the request runs beside the wait: a lost request (or its lost answer, retried) must
        # not hold the answer back when a periodic HEARTBEAT already says so
        asked = asyncio.ensure_future(
            self.command_long(MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HEARTBEAT)
        )
        try:
            reported = await self._core.requests.wait_until(
                lambda: self._telemetry.armed == arm, self.arm_confirm_timeout_s
            )
        finally:
            await cancel_and_wait(asked)
        elapsed_ms = accepted.elapsed_ms + (self._core.now() - started_s) * 1e3
        if reported:
            return dataclasses.replace(accepted, elapsed_ms=elapsed_ms)
        state = "disarmed" if arm else "armed"
        return dataclasses.replace(
            accepted, outcome=CommandOutcome.NOT_CONFIRMED, elapsed_ms=elapsed_ms,
            reason=f"accepted, but the vehicle still reports {state}",
        )  # fmt: skip

    async def takeoff(self, altitude_rel_m: float | None = None) -> CommandResult:
        """Climb to altitude_rel_m above home (None: PX4's MIS_TAKEOFF_ALT). Above the
        envelope: SetpointRejected, nothing sent."""
        check_takeoff_altitude(self.envelope, altitude_rel_m)
        alt_amsl = NAN
        if altitude_rel_m is not None:
            home_alt = self._home_alt_amsl()
            if home_alt is None:
                return not_sent(MAV_CMD_NAV_TAKEOFF, "no home position yet")
            alt_amsl = home_alt + altitude_rel_m
        started_s = self._core.now()
        if self._known_disarmed(started_s):
            return await self._arm_and_take_off(alt_amsl)
        # only a climb, armed, confirms it: PX4 still accepts the takeoff (it only switches to
        # TAKEOFF) if it disarmed itself on the ground meanwhile (COM_DISARM_PRFLT)
        confirm = Confirmation(
            reached=self._taking_off,
            timeout_s=self.mode_confirm_timeout_s,
            explain=lambda _s: self._why_not_taking_off(),
            aborted=lambda: self._disarmed_since(started_s),
            aborted_outcome=CommandOutcome.NOT_CONFIRMED,
        )
        return await self._core.requests.command_long(
            MAV_CMD_NAV_TAKEOFF, NAN, NAN, NAN, NAN, NAN, NAN, alt_amsl, confirm=confirm
        )

    async def _arm_and_take_off(self, alt_amsl: float) -> CommandResult:
        """QGroundControl's takeoff (PX4FirmwarePlugin::guidedModeTakeoff): NAV_TAKEOFF
        switches the disarmed vehicle to TAKEOFF from whatever mode it was left in, PX4 arms
        there, and arming starts the climb. A refused arm is answered as PX4 gave it, and the
        vehicle is put back in the mode it was in: left in TAKEOFF, the next arm (a pilot's
        Arm, once PX4 is ready) would start a climb nobody asked for then."""
        t = self._telemetry
        mode_before = t.mode
        in_takeoff = Confirmation(
            reached=lambda: t.mode in _TAKING_OFF_MODES,
            timeout_s=self.mode_confirm_timeout_s,
            explain=lambda _s: f"accepted, but the vehicle still reports {t.mode}",
        )
        switched = await self._core.requests.command_long(
            MAV_CMD_NAV_TAKEOFF, NAN, NAN, NAN, NAN, NAN, NAN, alt_amsl, confirm=in_takeoff
        )
        if not switched.ok:
            return switched
        armed = await self._arm_disarm(True, False)
        if not armed.ok:
            await self._put_back_mode(mode_before)
            return armed
        started_s = self._core.now()
        climbing = await self._core.requests.wait_until(
            self._taking_off, self.mode_confirm_timeout_s
        )
        elapsed_ms = switched.elapsed_ms + armed.elapsed_ms + (self._core.now() - started_s) * 1e3
        if climbing:
            return dataclasses.replace(switched, elapsed_ms=elapsed_ms)
        return dataclasses.replace(
            switched, outcome=CommandOutcome.NOT_CONFIRMED, elapsed_ms=elapsed_ms,
            reason=self._why_not_taking_off(),
        )  # fmt: skip

    async def _put_back_mode(self, mode: str) -> None:
        """Back to ``mode`` after a takeoff whose arming was refused (best effort: a mode
        PX4 does not take back, or an unknown one, is logged and left)."""
        if mode in _TAKING_OFF_MODES or self._telemetry.armed:
            return
        try:
            back = await self._set_mode_once(mode)
        except modes.UnknownModeError:
            log.warning("takeoff refused: left in %s (%s is not a mode to ask for)",
                        self._telemetry.mode, mode)  # fmt: skip
            return
        if not back.ok:
            log.warning("takeoff refused: %s not taken back (%s)", mode, back.outcome.name)

    def _taking_off(self) -> bool:
        t = self._telemetry
        return t.armed and (t.mode in _TAKING_OFF_MODES or t.landed_state in _IN_AIR_STATES)

    async def land(self) -> CommandResult:
        return await self.command_long(MAV_CMD_NAV_LAND)

    async def return_to_launch(self) -> CommandResult:
        return await self.command_long(MAV_CMD_NAV_RETURN_TO_LAUNCH)

    async def hold(self) -> CommandResult:
        return await self.set_mode("HOLD")

    async def set_mode(self, mode: str) -> CommandResult:
        """DO_SET_MODE, ACCEPTED only once the vehicle reports the mode. Accepted but not
        entered (PX4: OFFBOARD asked for just as AUTO.TAKEOFF ends, the vehicle ends in
        HOLD) is asked once more before it is NOT_CONFIRMED with the mode observed."""
        first = await self._set_mode_once(mode.upper())
        if first.outcome is not CommandOutcome.NOT_CONFIRMED:
            return first
        second = await self._set_mode_once(mode.upper())
        if second.outcome is not CommandOutcome.NOT_CONFIRMED:
            return second
        return dataclasses.replace(
            second,
            elapsed_ms=first.elapsed_ms + second.elapsed_ms,
            reason=f"accepted twice, but the vehicle still reports {self._telemetry.mode}",
        )

    async def _set_mode_once(self, target: str) -> CommandResult:
        main, sub = modes.main_sub_from_name(target)
        t = self._telemetry
        confirm = Confirmation(
            reached=lambda: t.mode == target,
            timeout_s=self.mode_confirm_timeout_s,
            explain=lambda _s: f"accepted, but the vehicle still reports {t.mode}",
        )
        return await self._core.requests.command_long(
            MAV_CMD_DO_SET_MODE, modes.set_mode_base_mode(t.armed), main, sub,
            confirm=confirm, name=f"SET_MODE:{target}",
        )  # fmt: skip

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
        """DO_REPOSITION as COMMAND_INT (degE7 is exact; float degrees are not). Outside
        the envelope: SetpointRejected, nothing sent."""
        if alt_amsl_m is not None and alt_rel_m is not None:
            raise ValueError("give alt_amsl_m or alt_rel_m, not both")
        check_reposition(
            self.envelope, self._telemetry.home, lat_deg, lon_deg,
            alt_amsl_m=alt_amsl_m, alt_rel_m=alt_rel_m,
        )  # fmt: skip
        alt = NAN if alt_amsl_m is None else alt_amsl_m
        if alt_rel_m is not None:
            home_alt = self._home_alt_amsl()
            if home_alt is None:
                return not_sent(MAV_CMD_DO_REPOSITION, "no home position yet")
            alt = home_alt + alt_rel_m
        where = CommandInt(MAV_FRAME_GLOBAL, _deg_e7(lat_deg), _deg_e7(lon_deg), alt)
        return await self._core.requests.command_int(
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
        """PX4 acks at once; with wait, resolve when EXTENDED_SYS_STATE shows the end state.
        Back where it started after a transition means PX4 aborted it (quadchute, timeout).
        A vehicle that is not a VTOL never answers, so it is refused without asking."""
        t = self._telemetry
        if self._core.mav_type not in _VTOL_TYPES and t.vtol_state == 0:
            name = enum_name("MAV_TYPE", self._core.mav_type, "MAV_TYPE_")
            return not_sent(
                MAV_CMD_DO_VTOL_TRANSITION,
                f"not a VTOL ({name}): PX4 does not answer a transition on it",
            )
        target = MAV_VTOL_STATE_FW if to_fixed_wing else MAV_VTOL_STATE_MC
        opposite = MAV_VTOL_STATE_MC if to_fixed_wing else MAV_VTOL_STATE_FW
        in_transition = False

        def aborted() -> bool:
            nonlocal in_transition
            in_transition = in_transition or t.vtol_state in (
                MAV_VTOL_STATE_TRANSITION_TO_FW,
                MAV_VTOL_STATE_TRANSITION_TO_MC,
            )
            return in_transition and t.vtol_state == opposite

        confirm = Confirmation(
            reached=lambda: t.vtol_state == target,
            timeout_s=timeout_s,
            explain=lambda s: f"vtol_state is {VTOL_STATE_NAMES[t.vtol_state]} after {s:.1f} s",
            aborted=aborted,
        )
        return await self._core.requests.command_long(
            MAV_CMD_DO_VTOL_TRANSITION, target, 1 if immediate else 0,
            confirm=confirm if wait else None,
        )  # fmt: skip

    async def set_gps_origin(
        self, lat_deg: float, lon_deg: float, alt_amsl_m: float
    ) -> CommandResult:
        """SET_GPS_GLOBAL_ORIGIN is a message, not a command: PX4 answers with
        GPS_GLOBAL_ORIGIN, so that echo is the confirmation."""
        lat_e7, lon_e7 = _deg_e7(lat_deg), _deg_e7(lon_deg)
        core = self._core

        def build() -> mavlink.MAVLink_message:
            # time_usec is a wall-clock (UNIX) time
            return core.mav.set_gps_global_origin_encode(
                core.sysid, lat_e7, lon_e7, round(alt_amsl_m * 1e3), int(time.time() * 1e6)
            )

        def echoed() -> bool:
            o = self._telemetry.origin
            return (o is not None and (_deg_e7(o.lat_deg), _deg_e7(o.lon_deg)) == (lat_e7, lon_e7)
                    and abs(o.alt_amsl_m - alt_amsl_m) < 0.01)  # fmt: skip

        return await core.requests.message(
            "SET_GPS_GLOBAL_ORIGIN", MAVLINK_MSG_ID_SET_GPS_GLOBAL_ORIGIN, build, echoed,
            timeout_s=self.origin_timeout_s,
        )  # fmt: skip

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
            here = self._telemetry.global_position
            alt_amsl_m = here.alt_amsl_m if here is not None else NAN
        where = CommandInt(MAV_FRAME_GLOBAL, _deg_e7(lat_deg), _deg_e7(lon_deg), alt_amsl_m)
        return await self._core.requests.command_int(MAV_CMD_DO_SET_HOME, where, 0)

    def _known_disarmed(self, now_s: float) -> bool:
        """Reported disarmed, with no arm of ours since that the reports may not show yet."""
        t = self._telemetry
        if t.armed or t.armed_changed_s is None:
            return False
        armed_s = self._arm_accepted_s
        unreported_arm = (armed_s is not None and armed_s >= t.armed_changed_s
                          and now_s - armed_s < ARMED_REPORT_PERIOD_S)  # fmt: skip
        return not unreported_arm

    def _disarmed_since(self, since_s: float) -> bool:
        t = self._telemetry
        return not t.armed and t.armed_changed_s is not None and t.armed_changed_s >= since_s

    def _why_not_taking_off(self) -> str:
        t = self._telemetry
        if t.armed:
            return f"accepted, but the vehicle reports {t.mode}, {t.landed_state_name}"
        disarmed_s = t.disarmed_s
        ours = self._disarm_accepted_s is not None and (
            disarmed_s is None or self._disarm_accepted_s >= disarmed_s - ARMED_REPORT_PERIOD_S
        )
        if disarmed_s is None or ours:
            return "accepted, but the vehicle is disarmed: arm it, then take off"
        ago_s = self._core.now() - disarmed_s
        return (
            f"accepted, but the vehicle disarmed itself {ago_s:.0f} s ago (PX4 disarms a "
            "vehicle left on the ground armed, COM_DISARM_PRFLT): arm again, then take off"
        )

    def _home_alt_amsl(self) -> float | None:
        home = self._telemetry.home
        return home.alt_amsl_m if home is not None else None
