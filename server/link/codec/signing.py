"""MAVLink 2 message signing on a link: the key, the replay window, what was rejected.

pymavlink does the cryptography: a link's codecs (the one that packs what the link sends
and the transports' decoders) share one ``MAVLinkSigning`` state, so everything the link
sends is signed and every frame it receives is checked before it reaches a vehicle or the
transport's peer routing. Checks follow PX4 (main branch, ``mavlink_sign_control.cpp`` and
the "MAVLink Message Signing" page):

- no key: nothing is signed, everything is accepted (signed frames are not checked);
- a key: unsigned or badly signed frames are rejected, except the allowlist PX4 also
  accepts unsigned (HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE, COLLISION), so a vehicle that
  has no key yet is still seen, and can be given one;
- replay: a frame whose timestamp is not newer than the last one of its stream (link id,
  system, component) is rejected, and so is a new stream more than a minute behind our
  clock (pymavlink's window).

The key is provisioned on the vehicle with SETUP_SIGNING (``signing_provision``), lives
in a key file that ``signing_keys.SigningKeyStore`` writes with mode 0600, and the signing
timestamp is persisted next to it (written every ``PERSIST_INTERVAL_S`` and at close, with
a margin) so a restarted server never signs with a timestamp it has used before. Neither
the key nor SETUP_SIGNING ever reaches a log or the tlog.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.signing_keys import SigningKeyStore, signing_timestamp

log = logging.getLogger(__name__)

MAVLINK_MSG_ID_SETUP_SIGNING = mavlink.MAVLINK_MSG_ID_SETUP_SIGNING
# PX4 accepts these unsigned even with a key (docs: "Unsigned Message Allowlist").
UNSIGNED_ALLOWLIST = frozenset(
    {
        mavlink.MAVLINK_MSG_ID_HEARTBEAT,
        mavlink.MAVLINK_MSG_ID_RADIO_STATUS,
        mavlink.MAVLINK_MSG_ID_ADSB_VEHICLE,
        mavlink.MAVLINK_MSG_ID_COLLISION,
    }
)
# the signing timestamp is persisted this often (and at close)
PERSIST_INTERVAL_S = 10.0
# pymavlink rejects a new stream this far behind our timestamp (one minute).
NEW_STREAM_WINDOW_TICKS = 6000 * 1000
# A vehicle counts as talking signed while its last verified frame is this recent.
SIGNED_RECENT_S = 3.0
_SIGNATURE_LEN = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN
# what LinkSigning counts as frames come, named as in SigningStats
_REJECTED = ("rejected_bad_signature", "rejected_replay", "rejected_unsigned")
_COUNTED = ("unsigned_in", *_REJECTED, "provisions")
_SIGNATURE_TIMESTAMP = struct.Struct("<IH")  # 48 bits after the link id


@dataclass(frozen=True)
class SigningStats:
    """A link's signing as the API shows it (never the key)."""

    enabled: bool  # this link signs what it sends and checks what it receives
    # every vehicle on the link sent a frame verified with our key within SIGNED_RECENT_S
    vehicles_signed: bool
    signed_in: int  # frames accepted with a good signature
    unsigned_in: int  # unsigned frames accepted (allowlist, or signing off)
    rejected: int  # the three below together
    rejected_bad_signature: int  # wrong key or forged
    rejected_replay: int  # timestamp not newer than its stream's last one
    rejected_unsigned: int  # unsigned and not on the allowlist
    provisions: int  # keys set, rotated or removed on the vehicles since start


class _SigningCodec(mavlink.MAVLink):  # type: ignore[misc]  # pymavlink is untyped
    """pymavlink's codec, telling the link why a signature failed.

    pymavlink records a stream's timestamp before it checks the HMAC; a forged frame with
    a far-future timestamp would then make every genuine frame of that stream look like a
    replay. The stream's timestamp is restored when the check fails, as MAVLink's C
    library (PX4's) does by checking the signature first.
    """

    def __init__(self, owner: LinkSigning, src_system: int = 0, src_component: int = 0) -> None:
        super().__init__(None, srcSystem=src_system, srcComponent=src_component)
        self.robust_parsing = True
        self.signing = owner.state
        self._owner = owner

    def check_signature(self, msgbuf: bytearray, srcSystem: int, srcComponent: int) -> bool:
        stream = (msgbuf[-_SIGNATURE_LEN], srcSystem, srcComponent)
        streams = self.signing.stream_timestamps
        before = streams.get(stream)
        if super().check_signature(msgbuf, srcSystem, srcComponent) is True:
            self._owner.verified(srcSystem)
            return True
        if before is None:
            streams.pop(stream, None)
        else:
            streams[stream] = before
        self._owner.failed(_is_replay(msgbuf, before, self.signing.timestamp))
        return False


def _is_replay(msgbuf: bytearray, stream_last: int | None, our_timestamp: int) -> bool:
    low, high = _SIGNATURE_TIMESTAMP.unpack(msgbuf[-12:-6])
    timestamp = int(low) + (int(high) << 32)
    if stream_last is not None:
        return timestamp <= stream_last
    return timestamp + NEW_STREAM_WINDOW_TICKS < our_timestamp


class LinkSigning:
    """One link's signing state, shared by its packer and its decoders."""

    def __init__(self, store: SigningKeyStore | None, link_id: int = 0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.store = store
        self.state = mavlink.MAVLinkSigning()
        self.state.link_id = link_id % 256
        self.state.allow_unsigned_callback = self._accept_unsigned
        self._clock = clock
        self._last_verified_s: dict[int, float] = {}
        self._last_unsigned_s: dict[int, float] = {}
        self._signature_failed = False
        self._counts: Counter[str] = Counter()  # by the names in _COUNTED
        self._persist_task: asyncio.Task[None] | None = None
        self._checker = _SigningCodec(self)
        # told after every key change (the link's sender process signs with the new one)
        self.on_key_change: Callable[[], None] | None = None
        key = store.key if store is not None else None
        self.use_key(key, store.start_timestamp() if store is not None else signing_timestamp())

    @property
    def enabled(self) -> bool:
        return self.state.secret_key is not None

    def codec(self, src_system: int = 0, src_component: int = 0) -> mavlink.MAVLink:
        """A pymavlink codec that signs and checks with this link's state."""
        return _SigningCodec(self, src_system, src_component)

    def use_key(self, key: bytes | None, timestamp: int | None = None) -> None:
        """Sign and check with ``key`` from now on (None: neither)."""
        state = self.state
        state.secret_key = key
        state.sign_outgoing = key is not None
        state.stream_timestamps.clear()
        if timestamp is not None:
            state.timestamp = max(state.timestamp, timestamp)
        self._last_verified_s.clear()
        self._last_unsigned_s.clear()
        if self.on_key_change is not None:
            self.on_key_change()

    def vehicle_signed(self, sysid: int) -> bool:
        last = self._last_verified_s.get(sysid)
        return last is not None and self._clock() - last <= SIGNED_RECENT_S

    def stats(self, sysids: Iterable[int]) -> SigningStats:
        ids = list(sysids)
        counts = self._counts
        return SigningStats(
            enabled=self.enabled,
            vehicles_signed=self.enabled and bool(ids) and all(map(self.vehicle_signed, ids)),
            signed_in=self.state.goodsig_count,
            rejected=sum(counts[name] for name in _REJECTED),
            **{name: counts[name] for name in _COUNTED},
        )

    def accepts_unknown(self, frame: bytes | bytearray) -> bool:
        """Whether to take a frame of a message id pymavlink does not know: pymavlink hands
        those over unchecked, so with a key their signature is checked here."""
        if not self.enabled:
            return True
        buf = bytearray(frame)
        signed = (buf[0] == mavlink.PROTOCOL_MARKER_V2
                  and buf[2] & mavlink.MAVLINK_IFLAG_SIGNED
                  and len(buf) >= mavlink.HEADER_LEN_V2 + 2 + _SIGNATURE_LEN)
        if not signed:
            self._counts["rejected_unsigned"] += 1
            return False
        if self._checker.check_signature(buf, buf[5], buf[6]):
            self.state.goodsig_count += 1
            return True
        self._signature_failed = False
        return False

    def vehicle_unsigned(self, sysid: int) -> bool:
        """An unsigned frame of ``sysid`` arrived since the last key change."""
        return sysid in self._last_unsigned_s

    def note_received(self, msg: mavlink.MAVLink_message) -> None:
        """Every frame the link accepted: those that came unsigned are counted here."""
        if msg.get_header().incompat_flags & mavlink.MAVLINK_IFLAG_SIGNED:
            return
        self._last_unsigned_s[msg.get_srcSystem()] = self._clock()
        if not self.enabled:
            self._counts["unsigned_in"] += 1  # with a key, the allowlist callback counted it

    # -- called by the codec while it decodes --
    def verified(self, src_system: int) -> None:
        self._last_verified_s[src_system] = self._clock()

    def failed(self, replay: bool) -> None:
        self._signature_failed = True
        if replay:
            self._counts["rejected_replay"] += 1
        else:
            self._counts["rejected_bad_signature"] += 1

    def _accept_unsigned(self, _mav: Any, msg_id: int) -> bool:
        # pymavlink asks this for unsigned frames and for frames whose signature failed
        # (those are already counted by the codec): only the allowlist passes.
        if self._signature_failed:
            self._signature_failed = False
            return False
        if msg_id in UNSIGNED_ALLOWLIST:
            self._counts["unsigned_in"] += 1
            return True
        self._counts["rejected_unsigned"] += 1
        return False

    # -- persistence --
    def start(self) -> None:
        if self.store is not None and self._persist_task is None:
            self._persist_task = asyncio.get_running_loop().create_task(
                self._persist_periodically(), name="signing-timestamp"
            )

    async def close(self) -> None:
        task, self._persist_task = self._persist_task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self.checkpoint()

    def checkpoint(self) -> None:
        if self.store is not None and self.enabled:
            self.store.checkpoint(self.state.timestamp)

    async def _persist_periodically(self) -> None:
        while True:
            await asyncio.sleep(PERSIST_INTERVAL_S)
            self.checkpoint()

    # -- provisioning --
    def count_provision(self) -> None:
        self._counts["provisions"] += 1
