"""Offboard: setpoints checked against the envelope, streamed, and the switch into and out
of PX4's OFFBOARD mode."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from server.link.codec.commands import CommandResult
from server.link.codec.setpoint_checks import (
    Envelope,
    Reference,
    SetpointRejected,
    check,
    vehicle_class,
)
from server.link.codec.setpoints import (
    PositionGlobal,
    PositionNed,
    SentSetpoint,
    Setpoint,
    encode,
    resolve,
)
from server.link.core.vehicle_core import VehicleCore
from server.link.plugins.action import Action
from server.link.plugins.telemetry import Telemetry
from server.link.stream.streamer import DEFAULT_RATE_HZ, SetpointStreamer, sender_event


class Offboard:
    """The setpoint stream of one vehicle and its OFFBOARD mode."""

    prestream_s = 1.0  # of setpoints before switching to OFFBOARD

    def __init__(
        self,
        core: VehicleCore,
        telemetry: Telemetry,
        action: Action,
        *,
        stream_rate_hz: float = DEFAULT_RATE_HZ,
    ) -> None:
        self._core = core
        self._telemetry = telemetry
        self._action = action
        self.setpoint: Setpoint | None = None  # what is streamed now, offsets resolved
        self.streamer = SetpointStreamer(
            core.send, rate_hz=stream_rate_hz, channel=core.stream_channel)  # its rate, stats
        self.streamer.on_sender_change = self._sender_changed
        self._engaged = False
        self._starting = False  # start() asking for OFFBOARD: its stream must not stop
        self._on_stream_start: list[Callable[[], None]] = []
        self.stopped_by_link: str | None = None  # why the link stopped the stream, if it did
        telemetry.on_mode(self._apply_stream_policy)
        core.on_connection(self._connection_changed)

    def on_stream_start(self, listener: Callable[[], None]) -> None:
        """Call ``listener()`` before a stopped stream starts (manual control stops then)."""
        self._on_stream_start.append(listener)

    def stop_stream(self, why: str) -> None:
        """Stop streaming (an event says why) without a mode change."""
        self._stop_stream(why)

    @property
    def envelope(self) -> Envelope:
        """The operator's limits, one set for every move (``Action.envelope``)."""
        return self._action.envelope

    # -- setpoints ------------------------------------------------------------------------
    def check(self, sp: Setpoint) -> Setpoint:
        """The setpoint with offsets resolved, or SetpointRejected."""
        return self._checked(sp, self.envelope)

    async def set_setpoint(self, sp: Setpoint) -> SentSetpoint:
        """Check, resolve offsets, send now and keep streaming it. The setpoint already
        being streamed only renews it: the stream keeps its schedule."""
        return self._stream(self._checked(sp, self.envelope))

    async def hold_position(self) -> SentSetpoint:
        """Stream "stay here": current position and yaw. Skips the envelope, since a
        vehicle already outside it must still be able to stop."""
        t = self._telemetry
        here = t.position_ned
        if here is None:
            raise SetpointRejected("no local position yet")
        yaw = t.attitude.yaw_deg if t.attitude is not None else None
        hold = PositionNed(here.north_m, here.east_m, here.down_m, yaw)
        return self._stream(self._checked(hold, Envelope(None, None, None, None)))

    def close(self) -> None:
        self.streamer.stop()

    def vehicle_rebooted(self) -> None:
        self._stop_by_link("vehicle rebooted")

    # -- link loss ------------------------------------------------------------------------
    def _connection_changed(self, connected: bool) -> None:
        """Lost: stop streaming at once, so PX4's own offboard-loss failsafe takes over and
        the vehicle does not fly off again by itself when the link heals (PX4 re-enters
        OFFBOARD whenever setpoints return). Back: the stream stays stopped until an
        operator sends a setpoint or starts offboard, and says so."""
        if not connected:
            self._stop_by_link("link lost")
        elif self.stopped_by_link is not None:
            self._core.publish_event("stream", {
                "active": False, "reason": f"{self.stopped_by_link}; link back",
                "text": "setpoint stream stays stopped after the link loss: send a setpoint "
                        "or start offboard to fly again",
            })  # fmt: skip

    def _sender_changed(self, change: dict[str, Any]) -> None:
        """The sender process failed (the stream went on from the thread) or is back."""
        self._core.publish_event("stream", sender_event("offboard", change))
        self._core.hub.notify()

    def _stop_by_link(self, why: str) -> None:
        if self.streamer.active:
            self.stopped_by_link = why
            self._stop_stream(why)

    # -- OFFBOARD mode --------------------------------------------------------------------
    async def start(self, sp: Setpoint | None = None) -> CommandResult:
        """Stream a setpoint (default: hold here) for at least prestream_s, then switch to
        OFFBOARD and wait until the vehicle reports it."""
        if sp is not None:
            await self.set_setpoint(sp)
        elif not self.streamer.active:
            await self.hold_position()
        # PX4 docs ask for > 1 s of stream first; the code needs less, so this satisfies both
        await asyncio.sleep(max(0.0, self.prestream_s - self.streamer.streaming_for_s()))
        # A mode PX4 changes to meanwhile (a takeoff ending in HOLD just as OFFBOARD is asked
        # for) must not stop this stream: set_mode asks once more, and PX4 refuses OFFBOARD
        # without it ("No offboard signal")
        self._starting = True
        try:
            result = await self._action.set_mode("OFFBOARD")
        finally:
            self._starting = False
        if not result.ok and not self._engaged:
            self._stop_stream("offboard refused")
        elif not result.ok:
            self._apply_stream_policy()  # what a mode change during the ask would have done
        return result

    async def stop(self, then_mode: str = "HOLD") -> CommandResult:
        """Switch to then_mode while still streaming, then stop the stream."""
        result = await self._action.set_mode(then_mode)
        if result.ok:
            self._stop_stream(f"left offboard for {then_mode}")
        return result

    # -- inside ---------------------------------------------------------------------------
    def _checked(self, sp: Setpoint, envelope: Envelope) -> Setpoint:
        t = self._telemetry
        p = t.position_ned
        here = None if p is None else (p.north_m, p.east_m, p.down_m)
        try:
            resolved = resolve(sp, here, t.attitude.yaw_deg if t.attitude is not None else None)
        except LookupError as exc:
            raise SetpointRejected(f"cannot convert the offset: {exc}") from None
        if isinstance(resolved, PositionGlobal) and t.global_position is None:
            # PX4 drops global setpoints silently until it has a global position
            raise SetpointRejected("no global position yet", field="lat_deg")
        kind = vehicle_class(self._core.mav_type, t.vtol_state_name)
        check(resolved, kind, envelope, self._reference())
        return resolved

    def _reference(self) -> Reference:
        home = self._telemetry.home
        if home is None:
            return Reference()
        return Reference(
            (home.north_m, home.east_m, home.down_m), (home.lat_deg, home.lon_deg, home.alt_amsl_m)
        )

    def _stream(self, resolved: Setpoint) -> SentSetpoint:
        core = self._core
        if not core.connected:
            raise SetpointRejected("the link to the vehicle is lost: nothing is streamed")
        self.stopped_by_link = None  # an operator's setpoint: the stream is theirs again
        time_boot_ms = int((core.now() - core.created_s) * 1000) & 0xFFFFFFFF
        msg, sent = encode(resolved, core.mav, core.sysid, core.compid, time_boot_ms)
        if self.streamer.active and resolved == self.setpoint:
            # a client repeating its setpoint (a renewal) must not add sends between ticks
            return sent
        if not self.streamer.active:
            for listener in self._on_stream_start:
                listener()
        self.setpoint = resolved
        self.streamer.stream(msg)
        core.hub.notify()
        return sent

    def _stop_stream(self, why: str) -> None:
        if self.streamer.active:
            self.streamer.stop()
            self._core.publish_event("stream", {
                "active": False, "reason": why, "text": f"setpoint stream stopped: {why}"})
        self.setpoint = None
        self._engaged = False

    def _apply_stream_policy(self) -> None:
        """Keep streaming while the user's intended mode is OFFBOARD (PX4 returns to it by
        itself after a blip); stop once the user chose another mode."""
        t = self._telemetry
        intended = t.user_mode if t.user_mode is not None else t.mode
        if intended == "OFFBOARD":
            self._engaged = True
        elif self._engaged and not self._starting:
            self._stop_stream(f"mode changed to {intended}")
