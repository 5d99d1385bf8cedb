"""PX4's events (EVENT, CURRENT_EVENT_SEQUENCE, REQUEST_EVENT), after mavlink_events.cpp.

Events carry a 32-bit id (component << 24 | sub id) and packed arguments whose meaning and
text live in PX4's events metadata; `sim/data/px4_events.json` holds the definitions of the
events this vehicle sends, copied from PX4 v1.16's generated all_events.json. Every event goes
into a buffer of the last EVENT_BUFFER_CAPACITY events and is sent on every link;
CURRENT_EVENT_SEQUENCE goes out every CURRENT_SEQUENCE_INTERVAL_S so receivers notice gaps and
ask for them with REQUEST_EVENT, answered from the buffer or with RESPONSE_EVENT_ERROR.
"""

from __future__ import annotations

import json
import struct
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from typing import Any

from sim.lib.mavlink_custom import CurrentEventSequenceMessage, CustomMessage

MAVLINK_MSG_ID_EVENT = 410
MAVLINK_MSG_ID_REQUEST_EVENT = 412
MAVLINK_MSG_ID_RESPONSE_EVENT_ERROR = 413
MAV_EVENT_ERROR_REASON_UNAVAILABLE = 0
MAV_EVENT_CURRENT_SEQUENCE_FLAGS_RESET = 1
MAV_COMP_ID_ALL = 0

# mavlink_events.h: EventBuffer(int capacity = 20), current_sequence_interval{3_s}
EVENT_BUFFER_CAPACITY = 20
CURRENT_SEQUENCE_INTERVAL_S = 3.0
EVENT_ARGUMENTS_LEN = 40
PX4_EVENTS_COMPONENT = 1

# events::Log levels (external | internal << 4)
LOG_CRITICAL = 2
LOG_ERROR = 3
LOG_WARNING = 4
LOG_INFO = 6
LOG_PROTOCOL = 8

_ARG_FORMATS = {"uint8_t": "B", "int8_t": "b", "uint16_t": "H", "int16_t": "h",
                "uint32_t": "I", "int32_t": "i", "uint64_t": "Q", "int64_t": "q", "float": "f"}


class EventMessage(CustomMessage):
    id = MAVLINK_MSG_ID_EVENT
    msgname = "EVENT"
    crc_extra = 160
    fieldnames = ("id", "event_time_boot_ms", "sequence", "destination_component",
                  "destination_system", "log_levels", "arguments")
    _wire = struct.Struct("<IIHBBB40s")


class ResponseEventErrorMessage(CustomMessage):
    id = MAVLINK_MSG_ID_RESPONSE_EVENT_ERROR
    msgname = "RESPONSE_EVENT_ERROR"
    crc_extra = 77
    fieldnames = ("sequence", "sequence_oldest_available", "target_system", "target_component",
                  "reason")
    _wire = struct.Struct("<HHBBB")


_REQUEST_EVENT = struct.Struct("<HHBB")


def log_levels(external: int, internal: int | None = None) -> int:
    """PX4's {events::Log, events::LogInternal}; one level stands for both."""
    return external | (external if internal is None else internal) << 4


@dataclass(frozen=True)
class EventDefinition:
    name: str
    event_id: int
    argument_formats: str


def _load_definitions() -> dict[str, EventDefinition]:
    text = resources.files("sim").joinpath("data/px4_events.json").read_text()
    metadata = json.loads(text)
    definitions: dict[str, EventDefinition] = {}
    for component_id, component in metadata["components"].items():
        enums = component.get("enums", {})
        for group in component["event_groups"].values():
            for sub_id, event in group["events"].items():
                formats = ""
                for argument in event.get("arguments", []):
                    arg_type = argument["type"].split("::")[-1]
                    formats += _ARG_FORMATS[enums[arg_type]["type"] if arg_type in enums
                                            else arg_type]
                event_id = int(component_id) << 24 | int(sub_id)
                definitions[event["name"]] = EventDefinition(event["name"], event_id, formats)
    return definitions


DEFINITIONS = _load_definitions()


@dataclass(frozen=True)
class Event:
    event_id: int
    time_boot_ms: int
    sequence: int
    log_levels: int
    arguments: bytes

    def message(self) -> EventMessage:
        return EventMessage(self.event_id, self.time_boot_ms, self.sequence, MAV_COMP_ID_ALL, 0,
                            self.log_levels, self.arguments)


@dataclass(frozen=True)
class RequestEvent:
    first_sequence: int
    last_sequence: int
    target_system: int
    target_component: int
    source_system: int
    source_component: int


def request_event_fields(msg: Any) -> RequestEvent | None:
    """A REQUEST_EVENT that pymavlink's dialect cannot name: the frame arrives as UNKNOWN
    with the raw MAVLink 2 bytes (header included, so the sender's ids are read there)."""
    data = bytes(getattr(msg, "data", b""))
    if len(data) < 12 or data[0] != 0xFD:
        return None
    if int.from_bytes(data[7:10], "little") != MAVLINK_MSG_ID_REQUEST_EVENT:
        return None
    payload = data[10:10 + data[1]].ljust(_REQUEST_EVENT.size, b"\0")
    first, last, target_system, target_component = _REQUEST_EVENT.unpack(payload[:6])
    return RequestEvent(first, last, target_system, target_component, data[5], data[6])


class EventLog:
    """The vehicle's event buffer and its send protocol (one for all links, as the uORB
    event topic is one; every link sends each event once)."""

    def __init__(self) -> None:
        self._send: Callable[[Any], None] | None = None
        self._active: Callable[[], bool] = lambda: False
        self._buffer: deque[Event] = deque(maxlen=EVENT_BUFFER_CAPACITY)
        self._latest_sequence = 0xFFFF
        self._sent_sequence = 0xFFFF
        self._now_s = 0.0
        self._last_current_sequence_s: float | None = None

    def attach(self, send: Callable[[Any], None], active: Callable[[], bool]) -> None:
        """Send on every link through `send` while `active()` (the vehicle has booted)."""
        self._send = send
        self._active = active

    @property
    def latest_sequence(self) -> int:
        return self._latest_sequence

    def buffered(self) -> tuple[Event, ...]:
        return tuple(self._buffer)

    def send(self, name: str, levels: int, *arguments: int | float) -> Event:
        definition = DEFINITIONS[name]
        packed = struct.pack("<" + definition.argument_formats, *arguments)
        self._latest_sequence = (self._latest_sequence + 1) & 0xFFFF
        event = Event(definition.event_id, round(self._now_s * 1000), self._latest_sequence,
                      levels, packed.ljust(EVENT_ARGUMENTS_LEN, b"\0"))
        self._buffer.append(event)
        return event

    def update(self, now_s: float) -> None:
        """Send what was published since the last update (PX4's mavlink thread does it on
        its next cycle, so an event follows the COMMAND_ACK of the command that caused it)."""
        self._now_s = now_s
        last = self._last_current_sequence_s
        if self._send is None or not self._active():
            self._sent_sequence = self._latest_sequence
            return
        for event in self._buffer:
            if 0 < (event.sequence - self._sent_sequence) & 0xFFFF <= len(self._buffer):
                self._send(event.message())
        self._sent_sequence = self._latest_sequence
        if last is None or now_s - last > CURRENT_SEQUENCE_INTERVAL_S:
            # SITL starts with the reset flag so receivers drop what they knew.
            self._send(self.current_sequence(force_reset=last is None))
            self._last_current_sequence_s = now_s

    def current_sequence(self, force_reset: bool = False) -> CustomMessage:
        flags = MAV_EVENT_CURRENT_SEQUENCE_FLAGS_RESET if force_reset or not self._buffer else 0
        message: CustomMessage = CurrentEventSequenceMessage(self._latest_sequence, flags)
        return message

    def handle_request(self, first: int, last: int, sysid: int, compid: int,
                       send: Callable[[Any], None]) -> None:
        """REQUEST_EVENT: each sequence from the buffer or a RESPONSE_EVENT_ERROR."""
        end = (last + 1) & 0xFFFF
        sequence = first
        while sequence != end:
            event = self._find(sequence)
            if event is not None:
                send(event.message())
            else:
                send(ResponseEventErrorMessage(sequence, self._oldest_after(sequence), sysid,
                                               compid, MAV_EVENT_ERROR_REASON_UNAVAILABLE))
            sequence = (sequence + 1) & 0xFFFF

    def _find(self, sequence: int) -> Event | None:
        for event in reversed(self._buffer):
            if event.sequence == sequence:
                return event
        return None

    def _oldest_after(self, sequence: int) -> int:
        """The buffered sequence closest after `sequence`, wrap-around aware, as PX4."""
        result = self._latest_sequence
        min_diff = 0xFFFF
        for event in self._buffer:
            diff = (event.sequence - sequence) & 0xFFFF
            if event.sequence != sequence and diff < min_diff:
                min_diff = diff
                result = event.sequence
        return result
