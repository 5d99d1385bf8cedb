"""Provisioning a signing key on vehicles with SETUP_SIGNING, and rolling it back."""

from __future__ import annotations

import asyncio
from typing import Protocol

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.commands import UNREAD_GRACE_S
from server.link.codec.signing import LinkSigning
from server.link.codec.signing_keys import SIGNING_KEY_BYTES

# provision(): tries, and how long each waits for the vehicle to answer with the new key.
PROVISION_TRIES = 3
PROVISION_CONFIRM_S = 1.5


class SigningLink(Protocol):
    """What :func:`provision` needs of a link."""

    signing: LinkSigning
    mav: mavlink.MAVLink

    def send(self, msg: mavlink.MAVLink_message) -> None: ...

    def input_pending(self) -> bool: ...


class ProvisionError(RuntimeError):
    """The vehicle never answered with the new key; the link kept its old one."""

    def __init__(self, sysids: list[int]) -> None:
        super().__init__(
            f"vehicle(s) {sysids} never answered signed with the new key "
            f"({PROVISION_TRIES} SETUP_SIGNING sent); the link keeps its previous key"
        )
        self.sysids = sysids


async def provision(
    link: SigningLink,
    sysids: list[int],
    key: bytes | None,
    *,
    confirm_s: float = PROVISION_CONFIRM_S,
    tries: int = PROVISION_TRIES,
) -> None:
    """Give ``sysids`` a new key (None: switch signing off) with SETUP_SIGNING, switch the
    link to it, and wait until each vehicle talks with it; ProvisionError after ``tries``.

    SETUP_SIGNING goes out under the current key (PX4 requires that once it has one), with
    our timestamp as the initial one, so the vehicle's next frames are newer than anything
    we have seen. A vehicle counts as switched when a frame of it verifies with the new key
    (switching off: when an unsigned frame of it arrives). After the last failed try the
    link goes back to its previous key and tells a vehicle that may have switched to do
    the same (:func:`_roll_back`).
    """
    signing = link.signing
    old_key = signing.state.secret_key
    for _ in range(tries):
        timestamp = signing.state.timestamp
        for sysid in sysids:
            link.send(link.mav.setup_signing_encode(
                sysid, 0, list(key or bytes(SIGNING_KEY_BYTES)), timestamp if key else 0,
            ))  # fmt: skip
        signing.use_key(key, timestamp)
        if await _switched(link, sysids, key is not None, confirm_s):
            signing.count_provision()
            signing.checkpoint()
            return
        signing.use_key(old_key)
    _roll_back(link, sysids, key, old_key, tries)
    raise ProvisionError(sysids)


def _roll_back(link: SigningLink, sysids: list[int], key: bytes | None,
               old_key: bytes | None, copies: int) -> None:
    """A vehicle may have taken ``key`` while every answer of it was lost: give it
    ``old_key`` back with SETUP_SIGNING signed with ``key``, or each end would drop the
    other's frames (HEARTBEAT too, badly signed) for good. A vehicle that never switched
    drops these; one that did takes the first and drops the other copies (wrong key)."""
    signing = link.signing
    timestamp = signing.state.timestamp
    signing.use_key(key, timestamp)
    for _ in range(copies):
        for sysid in sysids:
            link.send(link.mav.setup_signing_encode(
                sysid, 0, list(old_key or bytes(SIGNING_KEY_BYTES)), timestamp if old_key else 0,
            ))  # fmt: skip
    signing.use_key(old_key, timestamp)


async def _switched(link: SigningLink, sysids: list[int], signed: bool, timeout_s: float) -> bool:
    """Until every vehicle answered as asked, or ``timeout_s``; past it, a try goes on (at
    most UNREAD_GRACE_S) while frames wait unread, since the answer may be among them."""
    signing = link.signing
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    answered = signing.vehicle_signed if signed else signing.vehicle_unsigned
    while True:
        if all(answered(sysid) for sysid in sysids):
            return True
        now = loop.time()
        if now >= deadline and not (link.input_pending() and now < deadline + UNREAD_GRACE_S):
            return False
        await asyncio.sleep(0.02)
