"""provision()'s tries against a link that fell behind: an answer that waits unread at a
try's end is read first (at most UNREAD_GRACE_S), as the command layer does."""

from __future__ import annotations

import asyncio
import time

import pytest
from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.commands import UNREAD_GRACE_S
from server.link.codec.signing import LinkSigning
from server.link.codec.signing_provision import ProvisionError, provision

CONFIRM_S = 0.1


class BehindLink:
    """A link whose vehicle's answer sits unread (``pending``) until it is read."""

    def __init__(self, pending: bool) -> None:
        self.signing = LinkSigning(None)
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.sent: list[mavlink.MAVLink_message] = []
        self.pending = pending

    def send(self, msg: mavlink.MAVLink_message) -> None:
        self.sent.append(msg)

    def input_pending(self) -> bool:
        return self.pending

    def read_the_vehicles_answer(self) -> None:
        """The queued frame is read: an unsigned HEARTBEAT of vehicle 1."""
        vehicle = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        frame = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3).pack(vehicle)
        (msg,) = mavlink.MAVLink(None).parse_buffer(frame) or []
        self.signing.note_received(msg)
        self.pending = False


async def switch_off_answered_after(link: BehindLink, answer_s: float | None) -> float:
    """provision() switching signing off in one try; the time it took."""
    if answer_s is not None:
        asyncio.get_running_loop().call_later(answer_s, link.read_the_vehicles_answer)
    start = time.monotonic()
    await provision(link, [1], None, confirm_s=CONFIRM_S, tries=1)
    return time.monotonic() - start


async def test_an_answer_waiting_unread_at_the_tries_end_is_read_and_counts() -> None:
    link = BehindLink(pending=True)
    took_s = await switch_off_answered_after(link, CONFIRM_S + 0.3)
    assert CONFIRM_S + 0.3 <= took_s < CONFIRM_S + UNREAD_GRACE_S
    assert len(link.sent) == 1  # one SETUP_SIGNING, no roll-back


async def test_with_nothing_waiting_the_try_ends_on_time() -> None:
    link = BehindLink(pending=False)
    with pytest.raises(ProvisionError):
        await switch_off_answered_after(link, CONFIRM_S + 0.3)


async def test_a_link_that_never_catches_up_ends_the_try_after_the_grace() -> None:
    link = BehindLink(pending=True)
    start = time.monotonic()
    with pytest.raises(ProvisionError):
        await switch_off_answered_after(link, None)
    took_s = time.monotonic() - start
    assert CONFIRM_S + UNREAD_GRACE_S <= took_s < CONFIRM_S + UNREAD_GRACE_S + 1.0
