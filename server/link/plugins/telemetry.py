"""What a vehicle last reported: telemetry messages decoded into state parts (units in
names), STATUSTEXTs reassembled, events published when mode, arming or VTOL state change."""

from __future__ import annotations

import asyncio
import dataclasses
import math
import time
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec import modes
from server.link.codec.statustext import (
    RecentTexts,
    StatusTextAssembler,
    rtl_phase_announced,
    severity_name,
)
from server.link.core import state
from server.link.plugins.freshness import Freshness
from server.link.plugins.mavlink_values import (
    battery_state,
    enum_name,
    finite,
    flag_names,
    pwm_to_unit,
)

STATUSTEXT_KEEP = 20
MAV_LANDED_STATE_ON_GROUND = 1
# HEARTBEAT (1 Hz) shows failsafe mode changes late, so while CURRENT_MODE keeps coming it
# alone says the mode; HEARTBEAT takes over when it has been silent this long.
CURRENT_MODE_FRESH_S = 2.0

# What a state shows for the mode while it is not known since the link came back.
MODE_WITHHELD = "UNKNOWN"

class Telemetry(Freshness):
    """The latest reported value of each state part, kept by one handler per message type.

    The values are named as in VehicleState, whose telemetry part ``reported()`` gives."""

    # HEARTBEAT and CURRENT_MODE
    mode: str = "UNKNOWN"
    user_mode: str | None = None  # what the user chose (CURRENT_MODE.intended_custom_mode)
    armed: bool = False
    system_status: str = "UNINIT"
    # LOCAL_POSITION_NED, GLOBAL_POSITION_INT, ATTITUDE, POSITION_TARGET_LOCAL_NED
    position_ned: state.PositionNedState | None = None
    velocity_ned: state.VelocityNedState | None = None
    global_position: state.GlobalState | None = None
    attitude: state.AttitudeState | None = None
    target_ned: state.PositionNedState | None = None
    # EXTENDED_SYS_STATE's numbers (the *_name properties name them)
    landed_state: int = 0
    vtol_state: int = 0
    # VFR_HUD
    ground_speed_m_s: float | None = None
    air_speed_m_s: float | None = None
    climb_rate_m_s: float | None = None
    heading_deg: float | None = None
    # SERVO_OUTPUT_RAW or ACTUATOR_OUTPUT_STATUS, as 0..1
    actuator_outputs: tuple[float, ...] = ()
    # SYS_STATUS: PX4 sets MAV_SYS_STATUS_PREARM_CHECK in the health bits while arming is
    # possible in the current mode (streams/SYS_STATUS.hpp); None until a SYS_STATUS came
    ready_to_arm: bool | None = None
    # SYS_STATUS or BATTERY_STATUS, GPS_RAW_INT, HOME_POSITION, GPS_GLOBAL_ORIGIN, STATUSTEXT
    battery: state.BatteryState | None = None
    gps: state.GpsState | None = None
    home: state.HomeState | None = None
    origin: state.OriginState | None = None
    rtl_phase: str | None = None
    # ESTIMATOR_STATUS, SYS_STATUS's sensor health bits
    estimator: state.EstimatorState | None = None
    sensors_unhealthy: tuple[str, ...] | None = None

    def __init__(
        self,
        *,
        clock: Callable[[], float],
        texts: RecentTexts,
        publish: Callable[[str, dict[str, object]], None],
    ) -> None:
        super().__init__(clock)
        self._texts = texts
        self._publish = publish
        self._mode_listeners: list[Callable[[], None]] = []
        self._assembler = StatusTextAssembler(clock)
        self._expiry: asyncio.TimerHandle | None = None
        self._current_mode_s: float | None = None
        # when the reported armed state last changed (None: never reported yet)
        self.armed_changed_s: float | None = None
        self.disarmed_s: float | None = None  # when a reported arm last ended
        self.statustext: list[state.StatusText] = []
        self.handlers: dict[str, Callable[[Any], None]] = {
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
            "ESTIMATOR_STATUS": self._on_estimator_status,
        }
        for kind, handler in list(self.handlers.items()):
            self.handlers[kind] = self._timed(kind, handler)

    def _timed(self, kind: str, handler: Callable[[Any], None]) -> Callable[[Any], None]:
        def timed(msg: Any) -> None:
            self.received_s[kind] = self._clock()
            handler(msg)

        return timed

    def reported(self) -> dict[str, Any]:
        """The telemetry part of a VehicleState, by field name. After the link came back,
        the mode is withheld until the vehicle has told it again: the mode before a cut
        is the one most likely to have changed during it."""
        values = {name: getattr(self, name) for name in _REPORTED}
        stale = self.stale_fields()
        values.update(
            landed_state=self.landed_state_name,
            vtol_state=self.vtol_state_name,
            statustext=tuple(self.statustext),
            stale=stale,
        )
        if not self.lost and "mode" in stale:
            values.update(mode=MODE_WITHHELD, user_mode=None)
        return values

    def forget(self) -> None:
        """A rebooted vehicle: nothing it said before counts, home and origin included."""
        for name in _RESETTABLE:
            vars(self).pop(name, None)  # back to the class's "not reported" value
        self._current_mode_s = None
        self.armed_changed_s = self.disarmed_s = None
        self.forget_received()

    def on_mode(self, listener: Callable[[], None]) -> None:
        """Call ``listener()`` whenever a HEARTBEAT or CURRENT_MODE told the mode."""
        self._mode_listeners.append(listener)

    def _mode_reported(self) -> None:
        for listener in self._mode_listeners:
            listener()

    @property
    def landed_state_name(self) -> str:
        return state.LANDED_STATE_NAMES[self.landed_state]

    @property
    def vtol_state_name(self) -> str:
        return state.VTOL_STATE_NAMES[self.vtol_state]

    def _set_mode(self, mode: str) -> None:
        if mode != self.mode:
            previous, self.mode = self.mode, mode
            self._publish("mode", {"mode": mode, "previous": previous})
            if mode != "RTL":
                self.rtl_phase = None

    def _on_heartbeat(self, msg: mavlink.MAVLink_heartbeat_message) -> None:
        self.system_status = enum_name("MAV_STATE", msg.system_status, "MAV_STATE_")
        armed = bool(msg.base_mode & modes.MAV_MODE_FLAG_SAFETY_ARMED)
        if armed != self.armed or self.armed_changed_s is None:
            self.armed_changed_s = self._clock()
        if armed != self.armed:
            self.armed = armed
            if not armed:
                self.disarmed_s = self._clock()
            self._publish("armed", {"armed": armed})
        current_mode_fresh = (
            self._current_mode_s is not None
            and self._clock() - self._current_mode_s < CURRENT_MODE_FRESH_S
        )
        if msg.base_mode & modes.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and not current_mode_fresh:
            self._set_mode(modes.name_from_custom_mode(msg.custom_mode))
            self._mode_reported()

    def _on_current_mode(self, msg: mavlink.MAVLink_current_mode_message) -> None:
        self._current_mode_s = self._clock()
        self._set_mode(modes.name_from_custom_mode(msg.custom_mode))
        if msg.intended_custom_mode:
            self.user_mode = modes.name_from_custom_mode(msg.intended_custom_mode)
        self._mode_reported()

    def _on_extended_sys_state(self, msg: mavlink.MAVLink_extended_sys_state_message) -> None:
        if 0 <= msg.landed_state < len(state.LANDED_STATE_NAMES):
            self.landed_state = msg.landed_state
        # PX4 v1.16's RTL says nothing once down (its last text is "RTL: land at
        # destination"): touching down while returning is the end of the return
        touched_down = msg.landed_state == MAV_LANDED_STATE_ON_GROUND
        if self.mode == "RTL" and self.rtl_phase is not None and touched_down:
            self._set_rtl_phase("LANDED")
        if 0 <= msg.vtol_state < len(state.VTOL_STATE_NAMES) and msg.vtol_state != self.vtol_state:
            self.vtol_state = msg.vtol_state
            self._publish("vtol", {"vtol_state": state.VTOL_STATE_NAMES[msg.vtol_state]})

    def _on_local_position(self, msg: mavlink.MAVLink_local_position_ned_message) -> None:
        self.position_ned = state.PositionNedState(msg.x, msg.y, msg.z)
        self.velocity_ned = state.VelocityNedState(msg.vx, msg.vy, msg.vz)

    def _on_global_position(self, msg: mavlink.MAVLink_global_position_int_message) -> None:
        self.global_position = state.GlobalState(
            msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1e3, msg.relative_alt / 1e3
        )
        if msg.hdg != 0xFFFF:
            self.heading_deg = msg.hdg / 100.0

    def _on_attitude(self, msg: mavlink.MAVLink_attitude_message) -> None:
        d = math.degrees
        self.attitude = state.AttitudeState(
            d(msg.roll), d(msg.pitch), d(msg.yaw),
            d(msg.rollspeed), d(msg.pitchspeed), d(msg.yawspeed),
        )  # fmt: skip

    def _on_vfr_hud(self, msg: mavlink.MAVLink_vfr_hud_message) -> None:
        self.air_speed_m_s = msg.airspeed
        self.ground_speed_m_s = msg.groundspeed
        self.climb_rate_m_s = msg.climb
        self.heading_deg = float(msg.heading)

    def _on_sys_status(self, msg: mavlink.MAVLink_sys_status_message) -> None:
        self.ready_to_arm = bool(
            msg.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
        )
        unhealthy = (
            msg.onboard_control_sensors_present
            & msg.onboard_control_sensors_enabled
            & ~msg.onboard_control_sensors_health
            & ~mavlink.MAV_SYS_STATUS_PREARM_CHECK
        )
        self.sensors_unhealthy = flag_names("MAV_SYS_STATUS_SENSOR", unhealthy, "MAV_SYS_STATUS_")
        voltage_v = None if msg.voltage_battery == 0xFFFF else msg.voltage_battery / 1000.0
        battery = battery_state(voltage_v, msg.current_battery, msg.battery_remaining)
        if self.battery is not None:  # what only BATTERY_STATUS tells stays
            battery = dataclasses.replace(
                battery,
                consumed_mah=self.battery.consumed_mah,
                time_remaining_s=self.battery.time_remaining_s,
            )
        self.battery = battery

    def _on_battery_status(self, msg: mavlink.MAVLink_battery_status_message) -> None:
        cells = [v for v in msg.voltages if v != 0xFFFF]
        voltage_v = sum(cells) / 1000.0 if cells else None
        self.battery = dataclasses.replace(
            battery_state(voltage_v, msg.current_battery, msg.battery_remaining),
            # -1: not known; time_remaining 0: not known (a MAVLink 2 extension)
            consumed_mah=None if msg.current_consumed < 0 else float(msg.current_consumed),
            time_remaining_s=float(getattr(msg, "time_remaining", 0)) or None,
        )

    def _on_estimator_status(self, msg: mavlink.MAVLink_estimator_status_message) -> None:
        flags = flag_names("ESTIMATOR_STATUS_FLAGS", msg.flags, "ESTIMATOR_")
        self.estimator = state.EstimatorState(
            flags=flags,
            healthy=all(f in flags for f in _ESTIMATOR_NEEDED) and "GPS_GLITCH" not in flags,
            pos_horiz_ratio=finite(msg.pos_horiz_ratio),
            pos_vert_ratio=finite(msg.pos_vert_ratio),
            mag_ratio=finite(msg.mag_ratio),
        )

    def _on_gps_raw(self, msg: mavlink.MAVLink_gps_raw_int_message) -> None:
        self.gps = state.GpsState(
            enum_name("GPS_FIX_TYPE", msg.fix_type, "GPS_FIX_TYPE_"),
            msg.satellites_visible,
            None if msg.eph == 0xFFFF else msg.eph / 100.0,
        )

    def _on_home(self, msg: mavlink.MAVLink_home_position_message) -> None:
        self.home = state.HomeState(
            msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3, msg.x, msg.y, msg.z
        )

    def _on_origin(self, msg: mavlink.MAVLink_gps_global_origin_message) -> None:
        self.origin = state.OriginState(msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3)

    def _on_position_target(self, msg: mavlink.MAVLink_position_target_local_ned_message) -> None:
        self.target_ned = state.PositionNedState(msg.x, msg.y, msg.z)

    def _on_servo_output(self, msg: mavlink.MAVLink_servo_output_raw_message) -> None:
        raw = [getattr(msg, f"servo{i}_raw", 0) for i in range(1, 17)]
        self.actuator_outputs = tuple(pwm_to_unit(v) for v in raw if v)

    def _on_actuator_output(self, msg: mavlink.MAVLink_actuator_output_status_message) -> None:
        # PWM in microseconds, or already normalised: either way 0..1 for the dashboard
        values = msg.actuator[: msg.active]
        self.actuator_outputs = tuple(
            pwm_to_unit(v) if v > 2.0 else min(max(v, 0.0), 1.0) for v in values
        )

    def _on_statustext(self, msg: mavlink.MAVLink_statustext_message) -> None:
        text = msg.text if isinstance(msg.text, str) else msg.text.decode("utf-8", "replace")
        for severity, whole in self._assembler.feed(
            msg.severity, text.rstrip("\0"), getattr(msg, "id", 0), getattr(msg, "chunk_seq", 0)
        ):
            self._add_statustext(severity, whole)
        self._expire_later()

    def _expire_later(self) -> None:
        """A text whose last chunk got lost must still come out when no other text follows."""
        if not self._assembler.pending or self._expiry is not None:
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # fed outside a loop (a replay index, a unit test)
            return
        self._expiry = loop.call_later(self._assembler.timeout_s * 1.05, self._expire_texts)

    def _expire_texts(self) -> None:
        self._expiry = None
        for severity, whole in self._assembler.expire():
            self._add_statustext(severity, whole)
        self._expire_later()

    def _add_statustext(self, severity: int, text: str) -> None:
        entry = state.StatusText(time.time(), severity_name(severity), text)
        self.statustext.append(entry)
        del self.statustext[:-STATUSTEXT_KEEP]
        self._texts.add(severity, text)
        self._publish("statustext", {"severity": entry.severity, "text": text})
        phase = rtl_phase_announced(text)
        if phase is not None:
            self._set_rtl_phase(phase)

    def _set_rtl_phase(self, phase: str | None) -> None:
        if phase != self.rtl_phase:
            self.rtl_phase = phase
            self._publish("rtl", {"phase": phase})


# the reported values a reboot forgets (the class attributes hold their initial values)
_RESETTABLE = tuple(
    name for name, value in vars(Telemetry).items()
    if not name.startswith("_") and not callable(value) and not isinstance(value, property)
)
# what reported() copies as it is (the others it names or freezes)
_REPORTED = tuple(
    f.name
    for f in dataclasses.fields(state.VehicleState)
    if f.name in vars(Telemetry) and f.name not in ("landed_state", "vtol_state")
)


# an estimate a pilot can fly on: attitude, velocity and a horizontal position
_ESTIMATOR_NEEDED = ("ATTITUDE", "VELOCITY_HORIZ", "POS_HORIZ_REL")
