"""STATUSTEXT as real PX4 sends it: MAVLink 2 chunks (id, chunk_seq) of 50 bytes, a text in
one chunk with id 0, each text ending with a tab. Reassembled, stripped, and used whole as
the reason of a refusal."""

from __future__ import annotations

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.commands import CommandOutcome
from server.link.codec.statustext import StatusTextAssembler, rtl_phase_announced
from tests.link.conftest import ScriptedSession, wait_for

CRITICAL = mavlink.MAV_SEVERITY_CRITICAL
INFO = mavlink.MAV_SEVERITY_INFO
# A PX4 refusal whose last chunk holds only "t\t": a client that shows the last message
# alone shows "t\t"
REFUSAL = (
    "Arming denied: Resolve system health failures first: accel 0 not calibrated, "
    "compass 0 not consistent"
    "\t"
)


def _chunks(text: str) -> list[str]:
    return [text[i : i + 50] for i in range(0, len(text), 50)]


def _assembler() -> tuple[StatusTextAssembler, list[float]]:
    now = [0.0]
    return StatusTextAssembler(lambda: now[0], timeout_s=1.0), now


def test_the_refusal_whose_last_chunk_is_t_tab_is_whole_and_stripped() -> None:
    assembler, _ = _assembler()
    chunks = _chunks(REFUSAL)
    assert chunks[-1] == "t\t"

    out = [assembler.feed(CRITICAL, chunk, 9, seq) for seq, chunk in enumerate(chunks)]

    assert out[:-1] == [[] for _ in chunks[:-1]]
    assert out[-1] == [(CRITICAL, REFUSAL.rstrip("\t"))]


def test_a_one_chunk_text_has_id_0_and_loses_its_tab() -> None:
    assembler, _ = _assembler()

    assert assembler.feed(INFO, "Takeoff detected\t", 0, 0) == [(INFO, "Takeoff detected")]


def test_interleaved_ids_are_assembled_apart() -> None:
    assembler, _ = _assembler()
    first, second = "A" * 50 + "first end\t", "B" * 50 + "second end\t"
    a, b = _chunks(first), _chunks(second)

    assert assembler.feed(CRITICAL, a[0], 1, 0) == []
    assert assembler.feed(INFO, b[0], 2, 0) == []
    assert assembler.feed(INFO, "between\t", 0, 0) == [(INFO, "between")]
    assert assembler.feed(INFO, b[1], 2, 1) == [(INFO, second.rstrip())]
    assert assembler.feed(CRITICAL, a[1], 1, 1) == [(CRITICAL, first.rstrip())]


def test_a_lost_middle_chunk_shows_as_an_ellipsis_when_the_last_arrives() -> None:
    assembler, _ = _assembler()
    text = "M" * 50 + "N" * 50 + "end\t"
    chunks = _chunks(text)

    assembler.feed(CRITICAL, chunks[0], 4, 0)
    out = assembler.feed(CRITICAL, chunks[2], 4, 2)

    assert out == [(CRITICAL, "M" * 50 + "…" + "end")]


def test_a_lost_last_chunk_releases_the_text_after_the_timeout() -> None:
    assembler, now = _assembler()
    assembler.feed(CRITICAL, "L" * 50, 5, 0)
    now[0] = 0.9
    assert assembler.expire() == []
    assert assembler.pending

    now[0] = 1.1
    assert assembler.expire() == [(CRITICAL, "L" * 50)]
    assert not assembler.pending


async def test_a_text_missing_its_last_chunk_still_reaches_the_vehicle_state(
    scripted: ScriptedSession,
) -> None:
    # no later text arrives to push it out: the vehicle's own timer does
    scripted.peer.send(mavlink.MAVLink_statustext_message(CRITICAL, b"P" * 50, 6, 0))

    await wait_for(lambda: bool(scripted.vehicle.snapshot().statustext), 3.0, "the text")
    (text,) = scripted.vehicle.snapshot().statustext
    assert text.text == "P" * 50


async def test_a_refusal_carries_the_whole_chunked_text_as_its_reason(
    scripted: ScriptedSession,
) -> None:
    peer = scripted.peer

    def refuse(msg: mavlink.MAVLink_message) -> None:
        peer.ack(msg.command, mavlink.MAV_RESULT_TEMPORARILY_REJECTED)
        for seq, chunk in enumerate(_chunks(REFUSAL)):
            peer.send_later(0.01, mavlink.MAVLink_statustext_message(
                CRITICAL, chunk.encode(), 77, seq))  # fmt: skip

    peer.on_command = refuse
    result = await scripted.vehicle.arm()

    assert result.outcome is CommandOutcome.TEMPORARILY_REJECTED
    assert result.reason == REFUSAL.rstrip("\t")
    assert [t.text for t in scripted.vehicle.snapshot().statustext] == [REFUSAL.rstrip("\t")]


def test_an_rtl_text_names_its_phase_the_most_specific_keyword_first() -> None:
    assert rtl_phase_announced("RTL: start return at 520 m (30 m above destination)") == (
        "RETURNING"
    )
    assert rtl_phase_announced("RTL: move to land waypoint") == "MOVE_TO_LAND"
    assert rtl_phase_announced("RTL: land at destination") == "LANDING"
    assert rtl_phase_announced("RTL: hold on") is None  # an RTL text that names no phase
    assert rtl_phase_announced("Takeoff: climb to 10 m") is None  # not RTL's
