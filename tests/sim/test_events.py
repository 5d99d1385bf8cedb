"""PX4's events from the simulated vehicle: ids, arguments, log levels and the sequence
protocol (CURRENT_EVENT_SEQUENCE, REQUEST_EVENT, RESPONSE_EVENT_ERROR) as mavlink_events.cpp."""

from __future__ import annotations

import asyncio
import struct
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from sim.flight.commander import MAV_RESULT_TEMPORARILY_REJECTED
from sim.lib import modes
from sim.lib.events import EVENT_BUFFER_CAPACITY, CustomMessage
from tests.sim.conftest import Harness, RecordingLink
from tests.sim.test_endpoint import cluster, heartbeat, open_peer
from tests.waiting import wait_for

# ids from PX4 v1.16's all_events.json (component 1 << 24 | sub id)
ARM_DENIED_RESOLVE_FAILURES = 1 << 24 | 133277
CHECK_MODES_OFFBOARD_SIGNAL = 1 << 24 | 3087815
ARMING_CHECK_SUMMARY = 1 << 24 | 11047904
MODESWITCH_NOT_AVAIL = 1 << 24 | 10503063
FAILSAFE_ENTER_GENERIC = 1 << 24 | 14605264
DISARMED_BY = 1 << 24 | 16017271
COMMANDER_RTL = 1 << 24 | 3484900
LANDING_CURRENT_POS = 1 << 24 | 3322590


class RequestEvent(CustomMessage):
    id = 412
    msgname = "REQUEST_EVENT"
    crc_extra = 33
    fieldnames = ("first_sequence", "last_sequence", "target_system", "target_component")
    _wire = struct.Struct("<HHBB")


@dataclass
class Received:
    event_id: int
    time_boot_ms: int
    sequence: int
    log_levels: int
    arguments: bytes


def _payload(msg: Any, msg_id: int) -> bytes | None:
    """The payload of a message pymavlink's dialect lacks (UNKNOWN_<id>, raw frame bytes)."""
    if msg.get_type() != f"UNKNOWN_{msg_id}":
        return None
    data = bytes(msg.data)
    return data[10:10 + data[1]]


def events_of(link: RecordingLink) -> list[Received]:
    found = []
    for msg in link.sent:
        payload = _payload(msg, 410)
        if payload is not None:
            fields = struct.unpack("<IIHBBB40s", payload.ljust(53, b"\0"))
            found.append(Received(fields[0], fields[1], fields[2], fields[5], fields[6]))
    return found


def unpacked(link: RecordingLink, msg_id: int, wire: str) -> list[tuple[Any, ...]]:
    size = struct.calcsize(wire)
    return [struct.unpack(wire, p.ljust(size, b"\0")) for m in link.sent
            if (p := _payload(m, msg_id)) is not None]


def settle(h: Harness) -> None:
    """One MAVLink cycle: events go out on the cycle after they happen, as from PX4."""
    h.run(0.02)


def test_arming_in_offboard_without_setpoints_is_refused_with_px4s_events(
        harness: Harness) -> None:
    harness.set_mode(modes.OFFBOARD)
    settle(harness)
    harness.api.clear()
    harness.arm()
    assert events_of(harness.api) == []  # the ack goes first
    settle(harness)
    assert harness.last_ack(mavlink.MAV_CMD_COMPONENT_ARM_DISARM) == (
        MAV_RESULT_TEMPORARILY_REJECTED)
    denied = events_of(harness.api)
    assert [e.event_id for e in denied] == [ARM_DENIED_RESOLVE_FAILURES]
    assert denied[0].log_levels == 0x62  # Critical, internally Info
    assert denied[0].arguments == bytes(40)
    # the reason is the arming check PX4 reported before: No offboard signal, blocking the
    # offboard navigation mode group (bit 14), health component index 20 (system)
    log = harness.vehicle.commander.events
    check = [e for e in log.buffered() if e.event_id == CHECK_MODES_OFFBOARD_SIGNAL]
    assert check
    assert check[-1].log_levels == 0x33
    assert check[-1].arguments[:5] == struct.pack("<IB", 1 << 14, 20)


def test_setpoints_clear_the_offboard_check_with_a_new_report(harness: Harness) -> None:
    settle(harness)
    harness.api.clear()
    for _ in range(3):
        harness.local_ned(type_mask=0b110111111000)
        harness.run(0.1)
    ids = [e.event_id for e in events_of(harness.api)]
    assert ids[0] == ARMING_CHECK_SUMMARY
    assert CHECK_MODES_OFFBOARD_SIGNAL not in ids
    summary = events_of(harness.api)[0]
    can_arm = struct.unpack_from("<BIIII", summary.arguments)[3]
    assert can_arm & 1 << 14


def test_mode_refused_when_armed_names_the_mode(harness: Harness) -> None:
    # armed in Hold: PX4 refuses to arm in Position without stick input
    harness.set_mode(modes.AUTO_LOITER)
    harness.arm()
    settle(harness)
    harness.api.clear()
    harness.set_mode(modes.OFFBOARD)
    settle(harness)
    refused = [e for e in events_of(harness.api) if e.event_id == MODESWITCH_NOT_AVAIL]
    assert len(refused) == 1
    assert refused[0].log_levels == 0x62
    assert refused[0].arguments[:5] == struct.pack("<IB", modes.OFFBOARD.custom_mode, 7)


def test_mode_refusal_text_and_event_at_most_once_a_second(harness: Harness) -> None:
    # armed in Hold: PX4 refuses to arm in Position without stick input
    harness.set_mode(modes.AUTO_LOITER)
    harness.arm()
    settle(harness)
    harness.api.clear()
    for _ in range(2):  # Commander::printRejectMode: once within a second
        harness.set_mode(modes.OFFBOARD)
        settle(harness)
    refused = [e for e in events_of(harness.api) if e.event_id == MODESWITCH_NOT_AVAIL]
    assert len(refused) == 1
    assert harness.api.texts() == ["Switching to Offboard is currently not available"]
    harness.run(1.0)
    harness.set_mode(modes.OFFBOARD)
    settle(harness)
    assert len([e for e in events_of(harness.api) if e.event_id == MODESWITCH_NOT_AVAIL]) == 2


def test_run_prearm_checks_sends_the_check_report_again(harness: Harness) -> None:
    settle(harness)
    harness.api.clear()
    harness.command_long(mavlink.MAV_CMD_RUN_PREARM_CHECKS)
    assert harness.last_ack(mavlink.MAV_CMD_RUN_PREARM_CHECKS) == mavlink.MAV_RESULT_ACCEPTED
    settle(harness)
    ids = [e.event_id for e in events_of(harness.api)]
    assert ids[0] == ARMING_CHECK_SUMMARY  # the report though nothing changed
    assert CHECK_MODES_OFFBOARD_SIGNAL in ids


def test_offboard_loss_failsafe_and_preflight_auto_disarm(harness: Harness) -> None:
    harness.local_ned(type_mask=0b110111111000)
    harness.set_mode(modes.OFFBOARD)
    harness.arm()
    harness.api.clear()
    harness.run(2.0)
    failsafe = [e for e in events_of(harness.api) if e.event_id == FAILSAFE_ENTER_GENERIC]
    assert failsafe
    assert failsafe[0].log_levels == 0x42
    # as PX4 v1.16 SITL: the user's mode (OFFBOARD, 0x60000), action fallback_posctrl (2)
    assert failsafe[0].arguments[:5] == struct.pack("<IB", modes.OFFBOARD.custom_mode, 2)
    harness.run(10.0)
    disarmed = [e for e in events_of(harness.api) if e.event_id == DISARMED_BY]
    assert disarmed
    assert disarmed[0].arguments[0] == 7  # auto_disarm_preflight


def test_sequence_counts_up_and_current_sequence_goes_out_every_3_s(harness: Harness) -> None:
    settle(harness)
    harness.api.clear()
    harness.run(7.0)
    current = unpacked(harness.api, 411, "<HB")
    assert len(current) == 2
    harness.set_mode(modes.OFFBOARD)
    harness.arm()
    harness.arm()
    settle(harness)
    sequences = [e.sequence for e in events_of(harness.api)]
    assert sequences == [current[-1][0] + 1, current[-1][0] + 2]
    harness.run(3.1)
    assert unpacked(harness.api, 411, "<HB")[-1] == (sequences[-1], 0)


def test_first_current_sequence_has_the_reset_flag(make_harness: Any) -> None:
    h = make_harness(ready=False)
    h.run(2.0)
    assert unpacked(h.api, 411, "<HB")[0][1] == 1


def test_request_event_resends_from_the_buffer_or_answers_an_error(harness: Harness) -> None:
    harness.set_mode(modes.OFFBOARD)
    for _ in range(EVENT_BUFFER_CAPACITY + 5):
        harness.arm()
    latest = harness.vehicle.commander.events.latest_sequence
    oldest = (latest - EVENT_BUFFER_CAPACITY + 1) & 0xFFFF
    harness.gcs.clear()
    harness.deliver(RequestEvent(latest - 1, latest, 1, 1), harness.gcs)
    assert [e.sequence for e in events_of(harness.gcs)] == [latest - 1, latest]
    assert all(e.event_id == ARM_DENIED_RESOLVE_FAILURES for e in events_of(harness.gcs))
    harness.gcs.clear()
    harness.deliver(RequestEvent(oldest - 1, oldest, 1, 1), harness.gcs)
    errors = unpacked(harness.gcs, 413, "<HHBBB")
    # sequence, oldest available after it, target = the requester, reason UNAVAILABLE
    assert errors == [(oldest - 1, oldest, 255, 190, 0)]
    assert [e.sequence for e in events_of(harness.gcs)] == [oldest]
    harness.gcs.clear()
    harness.deliver(RequestEvent(latest, latest, 2, 1), harness.gcs)
    assert not harness.gcs.sent


def test_statustext_ends_with_a_tab_and_is_chunked_with_it(harness: Harness) -> None:
    # the text PX4 v1.16 SITL sends on a refused arm, seen as "...firs" + "t\t"
    text = "Arming denied: Resolve system health failures first"
    harness.api.clear()
    harness.vehicle.announce(mavlink.MAV_SEVERITY_CRITICAL, text)
    chunks = harness.api.of_type("STATUSTEXT")
    assert [c.text for c in chunks] == [text[:50], "t\t"]
    assert harness.api.raw_texts() == [text + "\t"]
    harness.api.clear()
    harness.vehicle.announce(mavlink.MAV_SEVERITY_INFO, "Landing detected")
    (single,) = harness.api.of_type("STATUSTEXT")
    assert single.text == "Landing detected\t"
    assert harness.api.texts() == ["Landing detected"]


async def test_over_udp_a_refused_arm_and_the_check_it_names() -> None:
    """Through the sim's UDP socket as a pymavlink client sees it (EVENT is UNKNOWN_410)."""
    peer = await open_peer()
    async with cluster(speed=5.0) as sim:
        await sim.wait_ready(timeout_s=5.0)
        await asyncio.sleep(0.2)  # the check report made at ready has gone out
        port = sim.instances[0].api_local_port
        peer.send(heartbeat(), port)
        peer.send(mavlink.MAVLink_command_long_message(
            1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, modes.OFFBOARD.main, 0, 0, 0, 0, 0), port)
        peer.received.clear()
        peer.send(mavlink.MAVLink_command_long_message(
            1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0), port)
        link = RecordingLink()

        def arm_denied() -> list[Any]:
            # among the events that come (the mode's refusal, arriving late on a loaded
            # machine, or a check report): the arm's refusal
            link.sent = [m for m in peer.received if m.get_type() == "UNKNOWN_410"]
            return [e for e in events_of(link) if e.event_id == ARM_DENIED_RESOLVE_FAILURES]

        await wait_for(arm_denied, 5.0, "the arm refused as an event")
        (denied,) = arm_denied()
        await wait_for(lambda: any(m.get_type() == "COMMAND_ACK" and m.command == 400
                                   for m in peer.received), 5.0, "the arm's answer")
        acks = [m for m in peer.received if m.get_type() == "COMMAND_ACK" and m.command == 400]
        assert [a.result for a in acks] == [MAV_RESULT_TEMPORARILY_REJECTED]
        peer.received.clear()
        peer.send(RequestEvent(0, denied.sequence, 1, 1), port)

        def resent_so_far() -> list[Any]:
            link.sent = list(peer.received)
            return [e for e in events_of(link) if e.sequence <= denied.sequence]

        # every answer comes (a loaded machine may spread them over a few heartbeats)
        await wait_for(lambda: len(resent_so_far()) > denied.sequence, 5.0, "every answer")
        # (a new check report follows our first heartbeat: no datalink check cleared)
        resent = resent_so_far()
        assert [e.sequence for e in resent] == list(range(denied.sequence + 1))
        check = [e for e in resent if e.event_id == CHECK_MODES_OFFBOARD_SIGNAL]
        assert check[-1].arguments[:5] == struct.pack("<IB", 1 << 14, 20)
    peer.close()


def test_land_and_return_commands_say_what_the_commander_does(harness: Harness) -> None:
    settle(harness)
    harness.api.clear()
    harness.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    harness.command_long(mavlink.MAV_CMD_NAV_LAND)
    settle(harness)
    said = {COMMANDER_RTL, LANDING_CURRENT_POS}  # besides the check report the mode changes
    infos = [(e.event_id, e.log_levels) for e in events_of(harness.api) if e.event_id in said]
    assert infos == [(COMMANDER_RTL, 0x66), (LANDING_CURRENT_POS, 0x66)]
