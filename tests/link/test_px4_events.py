"""PX4 events on the link: metadata discovery over MAVLink FTP and its cache, the sequence
protocol (gaps asked for, duplicates dropped), decoding, and refusal reasons."""

from __future__ import annotations

import asyncio
import json
import lzma
import struct
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from server.control.views import event_message
from server.link.codec.px4_messages import (
    MAVLINK_MSG_ID_COMPONENT_INFORMATION,
    MAVLINK_MSG_ID_COMPONENT_METADATA,
    MAVLINK_MSG_ID_REQUEST_EVENT,
    ComponentInformationMessage,
    ComponentMetadataMessage,
    CurrentEventSequenceMessage,
    EventMessage,
    ResponseEventErrorMessage,
)
from server.link.plugins.component_metadata import mavlink_crc32
from server.link.plugins.px4_events import EventDecoder
from tests.link.conftest import ScriptedSession, arm_as_sent, drain
from tests.link.ftp_server import FtpServer
from tests.waiting import wait_for

_BITFIELD = {"type": "uint32_t", "is_bitfield": True}
_HEALTH, _MODE_GROUPS = "px4::health_component_t", "px4::navigation_mode_group_t"


def _arguments(**types: str) -> list[dict[str, str]]:
    """An event's argument list, in order: name=type."""
    return [{"name": name, "type": kind} for name, kind in types.items()]


# every arming check's event: the mode groups it concerns, its health component
_CHECK_ARGUMENTS = _arguments(modes="navigation_mode_group_t", health_component_index="uint8_t")
# PX4's definitions (ids, names, texts, argument layouts) of the events used here
EVENTS_JSON: dict[str, Any] = {"version": 2, "components": {"1": {
    "namespace": "px4",
    "navigation_mode_groups": {"groups": {"2": [196608], "14": [393216]}},
    "enums": {
        "navigation_mode_t": {"type": "uint8_t", "entries": {
            "7": {"name": "offboard", "description": "Offboard"}}},
        "navigation_mode_group_t": {**_BITFIELD, "entries": {
            "4": {"name": "posctl"}, "16": {"name": "loiter"}, "16384": {"name": "offboard"}}},
        "health_component_t": {**_BITFIELD, "entries": {
            "1048576": {"name": "system", "description": "System"},
            "16777216": {"name": "global_position_estimate",
                         "description": "Global position estimate"}}},
    },
    "event_groups": {
        "default": {"events": {
            "133277": {"name": "commander_arm_denied_resolve_failures",
                       "message": "Arming denied: Resolve system health failures first"},
            "12208749": {"name": "navigator_mis_takeoff_too_low",
                         "message": "Mission rejected: takeoff altitude too low! "
                                    "Minimum: {1:.1m_v}",
                         "arguments": [{"name": "arg0", "type": "float"}]},
            "10503063": {"name": "commander_modeswitch_not_avail",
                         "type": "append_health_and_arming_messages",
                         "message": "Switching to mode '{2}' is currently not possible",
                         "arguments": [{"name": "arg0", "type": "uint32_t"},
                                       {"name": "arg1", "type": "px4::navigation_mode_t"}]},
            "7000": {"name": "param_marked", "message": "Check <param>COM_ARM_WO_GPS</param>"},
        }},
        "arming_check": {"events": {
            "11047904": {"name": "commander_arming_check_summary", "type": "summary",
                         "message": "Arming check summary event",
                         "arguments": _arguments(
                             chunk_idx="uint8_t", error=_HEALTH, warning=_HEALTH,
                             can_arm=_MODE_GROUPS, can_run=_MODE_GROUPS)},
            "3087815": {"name": "check_modes_offboard_signal", "message": "No offboard signal",
                        "arguments": _CHECK_ARGUMENTS},
            "10011251": {"name": "check_modes_global_pos",
                         "message": "Navigation error: No valid global position estimate",
                         "arguments": _CHECK_ARGUMENTS},
            "6801787": {"name": "check_rc_dl_no_dllink",
                        "message": "No connection to the ground control station",
                        "arguments": _CHECK_ARGUMENTS},
        }},
        "health": {"events": {
            "1914663": {"name": "commander_health_summary", "type": "summary",
                        "message": "Health report summary event",
                        "arguments": _arguments(
                            chunk_idx="uint8_t", is_present=_HEALTH, error=_HEALTH,
                            warning=_HEALTH)},
        }},
    },
}}}  # fmt: skip


def _event_id(name: str) -> int:
    """The id of an event of EVENTS_JSON: its component << 24 | its sub id."""
    for component_id, component in EVENTS_JSON["components"].items():
        for group in component["event_groups"].values():
            for sub_id, event in group["events"].items():
                if event["name"] == name:
                    return int(component_id) << 24 | int(sub_id)
    raise KeyError(name)


(ARM_DENIED, MODE_NOT_AVAILABLE, TAKEOFF_TOO_LOW, PARAM_MARKED, CHECK_SUMMARY,
 OFFBOARD_SIGNAL, NO_GLOBAL_POSITION, NO_GCS, HEALTH_SUMMARY) = map(_event_id, (
    "commander_arm_denied_resolve_failures", "commander_modeswitch_not_avail",
    "navigator_mis_takeoff_too_low", "param_marked", "commander_arming_check_summary",
    "check_modes_offboard_signal", "check_modes_global_pos", "check_rc_dl_no_dllink",
    "commander_health_summary",
))  # fmt: skip
OFFBOARD_MODE_GROUP = 1 << 14
POSCTL_MODE_GROUP, HOLD_MODE_GROUP = 1 << 2, 1 << 4
ALL_MODE_GROUPS = 0xFFFFFFFF
HEALTH_SYSTEM, HEALTH_GLOBAL_POSITION = 20, 24
# log_levels: external | internal << 4
CRITICAL, ERROR, WARNING, INFO, PROTOCOL = 0x22, 0x33, 0x44, 0x66, 0x88


class FakePx4:
    """A scripted PX4 that serves its events metadata and emits events."""

    def __init__(self, session: ScriptedSession, *, component_metadata: bool = True) -> None:
        self.peer = session.peer
        events_xz = lzma.compress(json.dumps(EVENTS_JSON).encode())
        general = json.dumps({"version": 1, "metadataTypes": [{
            "type": 4, "uri": "mftp://etc/extras/all_events.json.xz",
            "fileCrc": mavlink_crc32(events_xz)}]}).encode()  # fmt: skip
        self.general_crc = mavlink_crc32(general)
        self.ftp = FtpServer(self.peer, {"etc/extras/all_events.json.xz": events_xz,
                                         "etc/extras/component_general.json.xz":
                                         lzma.compress(general)})  # fmt: skip
        self.ftp.burst_packets = 20
        self.component_metadata = component_metadata
        self.seq = 0
        self.sent: dict[int, EventMessage] = {}
        self.requested: list[tuple[int, int]] = []
        self.peer.on_message = self._on_message
        self.peer.on_command = self._on_command

    def event(
        self, event_id: int, log_levels: int, arguments: bytes = b"", *, lose: bool = False
    ) -> None:
        self.seq += 1
        msg = EventMessage(event_id, 1000, self.seq, 0, 0, log_levels, arguments.ljust(40, b"\0"))
        self.sent[self.seq] = msg
        if not lose:
            self.peer.send(msg)

    def check_report(self, modes: int) -> None:
        """The offboard signal missing in `modes`; every other mode can arm."""
        can_arm = ALL_MODE_GROUPS & ~modes
        self.report(can_arm, [(OFFBOARD_SIGNAL, ERROR, modes, HEALTH_SYSTEM)])

    def report(self, can_arm: int, checks: list[tuple[int, int, int, int]]) -> None:
        """PX4's arming-check report: summary, one event per check (id, log levels, mode
        groups, health component index), health summary."""
        self.event(CHECK_SUMMARY, PROTOCOL, struct.pack("<BIIII", 0, 0, 0, can_arm, can_arm))
        for event_id, levels, modes, component in checks:
            self.event(event_id, levels, struct.pack("<IB", modes, component))
        self.event(HEALTH_SUMMARY, PROTOCOL, struct.pack("<BIII", 0, 0, 0, 0))

    def current_sequence(self) -> None:
        self.peer.send(CurrentEventSequenceMessage(self.seq, 0))

    def _on_message(self, msg: mavlink.MAVLink_message) -> None:
        self.ftp.handle(msg)
        if msg.get_type() == f"UNKNOWN_{MAVLINK_MSG_ID_REQUEST_EVENT}":
            raw = bytes(msg.get_msgbuf())
            first, last, _, _ = struct.unpack("<HHBB", raw[10 : 10 + raw[1]].ljust(6, b"\0"))
            self.requested.append((first, last))
            for seq in range(first, last + 1):
                if seq in self.sent:
                    self.peer.send(self.sent[seq])
                else:
                    self.peer.send(ResponseEventErrorMessage(seq, self.seq, 255, 190, 0))

    def _on_command(self, msg: mavlink.MAVLink_message) -> None:
        peer = self.peer
        if msg.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            peer.ack(msg.command, mavlink.MAV_RESULT_TEMPORARILY_REJECTED)
            self.event(ARM_DENIED, CRITICAL)
            return
        if msg.command == mavlink.MAV_CMD_DO_SET_MODE:
            peer.ack(msg.command, mavlink.MAV_RESULT_TEMPORARILY_REJECTED)
            custom_mode = int(msg.param2) << 16 | int(msg.param3) << 24
            self.event(MODE_NOT_AVAILABLE, CRITICAL, struct.pack("<IB", custom_mode, 7))
            return
        requested = int(msg.param1)
        if requested == MAVLINK_MSG_ID_COMPONENT_METADATA and not self.component_metadata:
            peer.ack(msg.command, mavlink.MAV_RESULT_DENIED)
            return
        peer.ack(msg.command, mavlink.MAV_RESULT_ACCEPTED)
        if msg.command != mavlink.MAV_CMD_REQUEST_MESSAGE:
            return
        uri = b"mftp://etc/extras/component_general.json.xz"
        if requested == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            peer.send(mavlink.MAVLink_autopilot_version_message(
                0, 0x011000FF, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0, [0] * 18))  # fmt: skip
        elif requested == MAVLINK_MSG_ID_COMPONENT_METADATA:
            peer.send(ComponentMetadataMessage(5, self.general_crc, uri))
        elif requested == MAVLINK_MSG_ID_COMPONENT_INFORMATION:
            peer.send(ComponentInformationMessage(5, self.general_crc, 0, uri, b""))


async def _loaded(scripted: ScriptedSession, tmp_path: Path, **kwargs: Any) -> FakePx4:
    px4 = FakePx4(scripted, **kwargs)
    plugin = scripted.vehicle.px4_events
    plugin.metadata.cache_dir = tmp_path
    plugin.ftp.timeout_s = plugin.metadata.answer_timeout_s = 0.1
    px4.current_sequence()  # the vehicle speaks events: the link fetches the metadata
    await wait_for(lambda: plugin.decoder is not None or plugin.metadata_error, 5.0, "metadata")
    assert plugin.metadata_error is None
    return px4


def _texts(queue: asyncio.Queue[Any]) -> list[str]:
    return [str(e.data["text"]) for e in drain(queue) if e.kind == "px4_event"]


def test_decoder_formats_arguments_and_strips_markup() -> None:
    decoder = EventDecoder(EVENTS_JSON)
    low = decoder.decode(TAKEOFF_TOO_LOW, struct.pack("<f", 2.5).ljust(40, b"\0"))
    assert low is not None
    assert low.text == "Mission rejected: takeoff altitude too low! Minimum: 2.5 m"
    marked = decoder.decode(PARAM_MARKED, bytes(40))
    assert marked is not None
    assert marked.text == "Check COM_ARM_WO_GPS"
    check = decoder.decode(OFFBOARD_SIGNAL, struct.pack("<IB", OFFBOARD_MODE_GROUP, 20))
    assert check is not None
    assert check.arguments["modes"] == OFFBOARD_MODE_GROUP
    assert decoder.decode(1 << 24 | 1, bytes(40)) is None


async def test_metadata_is_fetched_once_and_cached(
    scripted: ScriptedSession, tmp_path: Path
) -> None:
    px4 = await _loaded(scripted, tmp_path)
    assert px4.ftp.bursts > 0
    (cached,) = (tmp_path / "px4_events").iterdir()
    assert cached.name == f"011000ff_{px4.general_crc:08x}.json"
    plugin = scripted.vehicle.px4_events
    plugin.decoder = None
    plugin._load_task = None
    bursts = px4.ftp.bursts
    px4.current_sequence()
    await wait_for(lambda: plugin.decoder is not None, 5.0, "metadata from the cache")
    assert px4.ftp.bursts == bursts


async def test_component_information_when_metadata_is_refused(
    scripted: ScriptedSession, tmp_path: Path
) -> None:
    await _loaded(scripted, tmp_path, component_metadata=False)


async def test_events_are_published_logged_and_gaps_filled(
    scripted: ScriptedSession, tmp_path: Path
) -> None:
    px4 = await _loaded(scripted, tmp_path)
    queue = scripted.vehicle.subscribe_events()
    px4.event(TAKEOFF_TOO_LOW, WARNING, struct.pack("<f", 2.5))
    px4.event(PARAM_MARKED, INFO, lose=True)
    px4.event(PARAM_MARKED, INFO, lose=True)
    px4.event(ARM_DENIED, CRITICAL)
    await wait_for(lambda: px4.requested, 2.0, "REQUEST_EVENT")
    await scripted.vehicle_heard_all()
    assert px4.requested[0] == (2, 3)
    events = [e for e in drain(queue) if e.kind == "px4_event"]
    assert sorted(int(str(e.data["sequence"])) for e in events) == [1, 2, 3, 4]
    first = next(e for e in events if e.data["sequence"] == 1)
    assert first.data["log_level"] == "WARNING"
    assert first.data["arguments"] == {"arg0": 2.5}
    assert event_message(1, first) == {
        "type": "event", "vehicle": 1, "kind": "px4_event", "time_s": first.time_s,
        "data": {**first.data},
    }  # fmt: skip
    # a re-sent event nobody asked for is not shown twice
    scripted.peer.send(px4.sent[4])
    await scripted.vehicle_heard_all()
    assert _texts(queue) == []
    log = [m.text for m in scripted.vehicle.snapshot().statustext]
    assert "Arming denied: Resolve system health failures first" in log


async def test_lost_events_the_vehicle_no_longer_has(
    scripted: ScriptedSession, tmp_path: Path
) -> None:
    px4 = await _loaded(scripted, tmp_path)
    px4.event(PARAM_MARKED, INFO, lose=True)
    del px4.sent[px4.seq]  # overwritten in PX4's buffer
    px4.current_sequence()
    await wait_for(lambda: px4.requested, 2.0, "REQUEST_EVENT")
    await scripted.vehicle_heard_all()
    assert not scripted.vehicle.px4_events._missing


async def _offboard_blocked(scripted: ScriptedSession, tmp_path: Path) -> FakePx4:
    """A loaded vehicle whose arming checks report no offboard signal."""
    px4 = await _loaded(scripted, tmp_path)
    px4.check_report(OFFBOARD_MODE_GROUP)
    await scripted.vehicle_heard_all()
    return px4


async def test_arm_refusal_names_the_failing_check(
    scripted: ScriptedSession, tmp_path: Path
) -> None:
    await _offboard_blocked(scripted, tmp_path)
    # the check report is state, not a line of the message log
    assert not scripted.vehicle.snapshot().statustext
    scripted.peer.report_mode(0x60000, 0x60000)  # OFFBOARD
    await scripted.vehicle_heard_all()
    result = await arm_as_sent(scripted.vehicle)
    assert result.outcome.value == "TEMPORARILY_REJECTED"
    assert result.reason == (
        "Arming denied: Resolve system health failures first: No offboard signal"
    )
    # in a mode the check does not block, PX4's refusal text itself
    scripted.peer.report_mode(0x30000, 0x30000)  # POSCTL
    await scripted.vehicle_heard_all()
    result = await arm_as_sent(scripted.vehicle)
    assert result.reason == "Arming denied: Resolve system health failures first"


async def test_mode_refusal_names_the_checks_failing_in_that_mode(
    scripted: ScriptedSession, tmp_path: Path
) -> None:
    await _offboard_blocked(scripted, tmp_path)
    result = await scripted.vehicle.set_mode("OFFBOARD")
    assert result.outcome.value == "TEMPORARILY_REJECTED"
    assert result.reason == (
        "Switching to mode 'Offboard' is currently not possible: No offboard signal"
    )


async def test_an_earlier_refusals_text_is_not_the_reason(
    scripted: ScriptedSession, tmp_path: Path
) -> None:
    px4 = await _loaded(scripted, tmp_path)
    scripted.peer.send(
        mavlink.MAVLink_statustext_message(mavlink.MAV_SEVERITY_CRITICAL, b"Something else")
    )
    await scripted.vehicle_heard_all()
    px4.peer.on_command = lambda m: px4.peer.ack(m.command, mavlink.MAV_RESULT_DENIED)
    result = await scripted.vehicle.arm()
    assert result.outcome.value == "DENIED"
    assert result.reason is None


async def test_metadata_is_tried_again_after_a_failure(
    scripted: ScriptedSession, tmp_path: Path
) -> None:
    px4 = FakePx4(scripted)
    served = dict(px4.ftp.files)
    px4.ftp.files.clear()  # not there (yet)
    plugin = scripted.vehicle.px4_events
    plugin.metadata.cache_dir = tmp_path
    plugin.ftp.timeout_s = plugin.metadata.answer_timeout_s = 0.1
    plugin.retry_s = 0.0
    px4.current_sequence()
    await wait_for(lambda: plugin.metadata_error, 5.0, "the failure")
    assert "FileNotFound" in str(plugin.metadata_error)
    px4.ftp.files.update(served)
    px4.current_sequence()
    await wait_for(lambda: plugin.decoder is not None, 5.0, "metadata on the next try")
