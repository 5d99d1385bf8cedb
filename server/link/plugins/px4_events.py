"""PX4 events (EVENT, CURRENT_EVENT_SEQUENCE, REQUEST_EVENT, RESPONSE_EVENT_ERROR) decoded
to text with the vehicle's own events metadata.

PX4 reports why it refuses (arming checks, mode refusals, failsafes) mostly as EVENTs: an id,
a log level and packed arguments whose meaning and text are in the events JSON the vehicle
serves as component metadata. The receiver side follows libevents' receive protocol: each
EVENT carries a 16-bit sequence number; a gap (seen in a later EVENT or in the periodic
CURRENT_EVENT_SEQUENCE) is asked for with REQUEST_EVENT, the vehicle re-sends from its
buffer or answers RESPONSE_EVENT_ERROR when they are gone; re-sent duplicates are dropped.

The metadata is fetched the first time the vehicle shows it speaks events, so a vehicle
that never does costs no requests. Events that arrive before it is loaded are decoded once
it is. Decoding is pyulog's port of libevents' parser (argument unpacking, enums and
bitfields, "{1}" formatting, PX4's markup stripped).

A decoded event goes three ways: a ``px4_event`` vehicle event (text, log level, id,
arguments, group), the state's recent messages (the page's message log; not the arming and
health check reports, which PX4 repeats with every change) and, when it is a warning or
worse, the reason of a command refused just before.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pyulog.libevents_parse.parser import Parser  # type: ignore[import-untyped]

from server.link.codec.aio import cancel_and_wait
from server.link.codec.arming_checks import NAV_STATES, CheckReportReader, log_level_name
from server.link.codec.px4_messages import (
    MAV_EVENT_CURRENT_SEQUENCE_FLAGS_RESET,
    RequestEventMessage,
    event_arguments,
)
from server.link.codec.statustext import MAV_SEVERITY_WARNING
from server.link.core.state import StatusText
from server.link.core.vehicle_core import VehicleCore
from server.link.plugins.component_metadata import (
    ComponentMetadata,
    MetadataError,
    default_cache_dir,
)
from server.link.plugins.ftp import FtpClient
from server.link.plugins.telemetry import STATUSTEXT_KEEP, Telemetry

log = logging.getLogger(__name__)

# groups PX4 uses for the texts a user reads: plain events and the arming/health checks
_SHOWN_GROUPS = frozenset({"default", "arming_check", "health"})
_CHECK_GROUPS = ("arming_check", "health")
_LOG_LEVEL_PROTOCOL = 8
MAV_CMD_RUN_PREARM_CHECKS = 401
# PX4's event names of the refusal that points at the arming-check report
ARM_DENIED_RESOLVE_FAILURES = "commander_arm_denied_resolve_failures"
APPEND_CHECKS = "append_health_and_arming_messages"
_MAX_MISSING = 128  # a larger gap is not worth asking for
_KEEP_UNDECODED = 64
_SAME_TEXT_S = 1.0


def _newer(a: int, b: int) -> bool:
    """Sequence a comes after b (16-bit, wrapping)."""
    return 0 < (a - b) & 0xFFFF < 0x8000


@dataclass(frozen=True)
class DecodedEvent:
    name: str  # PX4's event name, e.g. "check_modes_offboard_signal"
    group: str  # "default", "arming_check", "health"
    text: str
    arguments: dict[str, object]  # by the argument names of the metadata
    # "append_health_and_arming_messages": a refusal whose first argument is the custom
    # mode asked for, to be read with the checks failing in that mode (as QGroundControl)
    type: str = ""


class EventDecoder:
    """PX4's events JSON → text for (id, argument bytes)."""

    def __init__(self, definitions: dict[str, Any]) -> None:
        self._parser = Parser()
        self._parser.load_definitions(definitions)
        self._parser.set_profile("normal")
        self._argument_names: dict[int, list[str]] = {}
        # PX4's custom_mode → navigation state, from its "navigation_mode_groups"
        self.nav_states: dict[int, int] = {}
        # health_component_t by bit index: PX4's description of each component
        self.health_components: dict[int, str] = {}
        for component_id, component in definitions.get("components", {}).items():
            health = component.get("enums", {}).get("health_component_t", {})
            for bit, entry in health.get("entries", {}).items():
                label = entry.get("description") or entry.get("name")
                self.health_components[int(bit).bit_length() - 1] = str(label)
            groups = component.get("navigation_mode_groups", {}).get("groups", {})
            for nav_state, custom_modes in groups.items():
                self.nav_states.update((int(mode), int(nav_state)) for mode in custom_modes)
            for group in component.get("event_groups", {}).values():
                for sub_id, event in group.get("events", {}).items():
                    event_id = int(component_id) << 24 | int(sub_id)
                    names = [
                        str(a.get("name", i))
                        for i, a in enumerate(event.get("arguments", []), start=1)
                    ]
                    self._argument_names[event_id] = names

    def decode(self, event_id: int, arguments: bytes) -> DecodedEvent | None:
        """The event's text and arguments, or None for an id the metadata lacks."""
        try:
            parsed = self._parser.parse(event_id, arguments)
        except Exception:  # a malformed definition or argument must not stop the link
            log.debug("event %d could not be decoded", event_id, exc_info=True)
            return None
        if parsed is None:
            return None
        names = self._argument_names.get(event_id, [])
        values = [parsed.argument_value(i) for i in range(parsed.num_arguments())]
        return DecodedEvent(
            str(parsed.name()),
            str(parsed.group()),
            str(parsed.message()),
            dict(zip(names, values, strict=False)),
            str(parsed.type() or ""),
        )


class Px4Events:
    """The events protocol of one vehicle and the metadata it needs."""

    reason_wait_s = 0.2  # PX4 sends the EVENT a few ms after the COMMAND_ACK
    retry_s = 30.0  # after the metadata could not be had, the next try

    def __init__(
        self, core: VehicleCore, telemetry: Telemetry, cache_dir: Path | None = None
    ) -> None:
        self._core = core
        self._telemetry = telemetry
        self.ftp = FtpClient(send=core.send, mav=core.mav, target=(core.sysid, core.compid))
        self.metadata = ComponentMetadata(core, self.ftp, cache_dir or default_cache_dir())
        self.decoder: EventDecoder | None = None
        self.metadata_error: str | None = None
        self._load_task: asyncio.Task[None] | None = None
        self._failed_s = 0.0
        self._undecoded: deque[Any] = deque(maxlen=_KEEP_UNDECODED)
        self._latest: int | None = None
        self._missing: set[int] = set()
        self.checks = CheckReportReader()
        self._refusal: tuple[float, DecodedEvent] | None = None
        core.requests.explainers.append(self._explain)
        core.on_message("FILE_TRANSFER_PROTOCOL", self.ftp.handle_message)
        core.on_message("EVENT", self._on_event)
        core.on_message("CURRENT_EVENT_SEQUENCE", self._on_current_sequence)
        core.on_message("RESPONSE_EVENT_ERROR", self._on_event_error)

    async def close(self) -> None:
        await cancel_and_wait(self._load_task)

    def reload(self) -> None:
        """A rebooted vehicle: its sequence starts again and its metadata (new firmware,
        perhaps) is fetched again."""
        if self._load_task is not None:
            self._load_task.cancel()
            self._load_task = None
        self.decoder = None
        self.metadata_error = None
        self._latest = None
        self._missing.clear()
        self.checks.forget()
        self._refusal = None
        self._start_loading()

    # -- the sequence protocol ----------------------------------------------------------
    def _on_event(self, msg: Any) -> None:
        if msg.destination_system not in (0, self._core.mav.srcSystem):
            return
        seq = msg.sequence
        if self._latest is None:
            self._latest = seq
        elif seq in self._missing:
            self._missing.discard(seq)  # a re-sent one we asked for
        elif _newer(seq, self._latest):
            self._ask_between(self._latest, seq)
            self._latest = seq
        else:
            return  # seen already (a re-send nobody here asked for)
        self._handle(msg)

    def _on_current_sequence(self, msg: Any) -> None:
        if msg.flags & MAV_EVENT_CURRENT_SEQUENCE_FLAGS_RESET or self._latest is None:
            # a restarted vehicle, or we just came: its older events are history
            self._missing.clear()
            self._latest = msg.sequence
        elif _newer(msg.sequence, self._latest):
            self._ask_between(self._latest, (msg.sequence + 1) & 0xFFFF)
            self._latest = msg.sequence
        elif self._missing:
            self._request(sorted(self._missing))  # the earlier request got lost
        self._start_loading()

    def _on_event_error(self, msg: Any) -> None:
        """The vehicle no longer has what was asked for: stop waiting for it."""
        oldest = msg.sequence_oldest_available
        gone = {s for s in self._missing if s == msg.sequence or _newer(oldest, s)}
        if gone:
            log.info("vehicle %d: %d events lost (buffer overrun)", self._core.sysid, len(gone))
        self._missing -= gone

    def _ask_between(self, after: int, before: int) -> None:
        """Request the events strictly between two sequence numbers."""
        gap = [(after + i) & 0xFFFF for i in range(1, (before - after) & 0xFFFF)]
        if not gap or len(gap) > _MAX_MISSING:
            return
        self._missing.update(gap)
        self._request(gap)

    def _request(self, sequences: list[int]) -> None:
        self._core.send(RequestEventMessage(
            sequences[0], sequences[-1], self._core.sysid, self._core.compid))  # fmt: skip

    # -- metadata and decoding ------------------------------------------------------------
    def _start_loading(self) -> None:
        if self.decoder is not None:
            return
        task = self._load_task
        if task is None or (task.done() and self._core.now() - self._failed_s > self.retry_s):
            self._load_task = asyncio.get_running_loop().create_task(
                self._load(), name=f"events-metadata:{self._core.sysid}"
            )

    async def _load(self) -> None:
        try:
            self.decoder = EventDecoder(await self.metadata.events())
            self.checks.health_components = self.decoder.health_components
        except (MetadataError, ValueError) as e:
            self.metadata_error = str(e)
            self._failed_s = self._core.now()
            log.warning("vehicle %d: no events metadata: %s", self._core.sysid, e)
            self._core.publish_event("px4_events_metadata", {"loaded": False, "error": str(e)})
            return
        self.metadata_error = None
        self._core.publish_event("px4_events_metadata", {"loaded": True})
        while self._undecoded:
            self._handle(self._undecoded.popleft())
        self._core.changed()
        # PX4 reports its arming checks when they change; the report sent before we
        # listened is asked for again, as QGroundControl does
        await self._core.requests.command_long(MAV_CMD_RUN_PREARM_CHECKS)

    def _handle(self, msg: Any) -> None:
        if self.decoder is None:
            self._undecoded.append(msg)
            self._start_loading()
            return
        level = msg.log_levels & 0x0F
        decoded = self.decoder.decode(msg.id, event_arguments(msg))
        if decoded is None:
            decoded = DecodedEvent("", "default", f"[unknown event {msg.id}]", {})
        elif decoded.group in _CHECK_GROUPS and self.checks.take(
            decoded.name, decoded.group, decoded.text, level, list(decoded.arguments.values())
        ):
            self._core.changed()
        if level >= _LOG_LEVEL_PROTOCOL or decoded.group not in _SHOWN_GROUPS:
            return
        self._core.publish_event("px4_event", {
            "id": msg.id, "sequence": msg.sequence, "name": decoded.name, "text": decoded.text,
            "log_level": log_level_name(level), "group": decoded.group,
            "arguments": decoded.arguments,
        })  # fmt: skip
        if decoded.group != "default":
            return  # the check reports repeat with every change: state, not log lines
        messages, now = self._telemetry.statustext, time.time()
        # PX4 sends some events also as STATUSTEXT (ending in a tab): the log shows one
        if not any(m.text == decoded.text and now - m.time_s < _SAME_TEXT_S for m in messages):
            messages.append(StatusText(now, log_level_name(level), decoded.text))
            del messages[:-STATUSTEXT_KEEP]
        if decoded.name and level <= MAV_SEVERITY_WARNING:
            self._refusal = (self._core.now(), decoded)

    # -- arming checks and refusal reasons ------------------------------------------------
    def failing_checks(self, nav_state: int | None = None) -> list[str]:
        """The texts of the arming checks that fail in a mode (PX4's navigation state;
        by default the vehicle's current mode)."""
        if nav_state is None:
            nav_state = NAV_STATES.get(self._telemetry.mode)
        return self.checks.failing(nav_state)

    async def _explain(self, started_s: float, reason: str | None) -> str | None:
        """A refused command's reason: PX4's event that follows the COMMAND_ACK, followed
        by the checks that fail when it points at them: in the current mode for "Arming
        denied: Resolve system health failures first", in the mode asked for when PX4
        marks the event so (a mode not available)."""
        if self.decoder is None:
            return reason

        def refused() -> bool:
            return self._refusal is not None and self._refusal[0] >= started_s

        if not refused():
            await self._core.wait_until(refused, self.reason_wait_s)
        if self._refusal is None or not refused():
            # PX4 explains after it got the command: a text from before is another story
            # (the refusal of the command before, say)
            earlier = [t for t, _, text in self._core.texts.items if text == reason]
            return None if earlier and max(earlier) < started_s else reason
        event = self._refusal[1]
        checks: list[str] = []
        if event.name == ARM_DENIED_RESOLVE_FAILURES:
            checks = self.failing_checks()
        elif event.type == APPEND_CHECKS:
            custom_mode = next(iter(event.arguments.values()), None)
            if isinstance(custom_mode, int) and custom_mode in self.decoder.nav_states:
                checks = self.failing_checks(self.decoder.nav_states[custom_mode])
        # both texts, as QGroundControl shows the refusal with the checks that fail
        return f"{event.text}: {'; '.join(checks)}" if checks else event.text
