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

The key is provisioned on the vehicle with SETUP_SIGNING (:func:`provision`), lives in a
key file that :class:`SigningKeyStore` writes with mode 0600, and the signing timestamp is
persisted next to it (written every ``PERSIST_INTERVAL_S`` and at close, with a margin) so
a restarted server never signs with a timestamp it has used before. Neither the key nor
SETUP_SIGNING ever reaches a log or the tlog.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import secrets
import struct
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from pymavlink.dialects.v20 import development as mavlink

log = logging.getLogger(__name__)

SIGNING_KEY_BYTES = 32
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
# MAVLink signing timestamps count 10 µs since 2015-01-01T00:00:00Z.
SIGNING_EPOCH_UNIX_S = 1_420_070_400
SIGNING_TICKS_PER_S = 100_000
# The persisted timestamp runs this far ahead of the one in use, so frames signed after
# the last write (a crash) still lie below what a restart starts from: 60 s of ticks, far
# more than a link can sign between two writes (one tick per frame).
PERSIST_MARGIN_TICKS = 60 * SIGNING_TICKS_PER_S
PERSIST_INTERVAL_S = 10.0
# pymavlink rejects a new stream this far behind our timestamp (one minute).
NEW_STREAM_WINDOW_TICKS = 6000 * 1000
# A vehicle counts as talking signed while its last verified frame is this recent.
SIGNED_RECENT_S = 3.0
# provision(): tries, and how long each waits for the vehicle to answer with the new key.
PROVISION_TRIES = 3
PROVISION_CONFIRM_S = 1.5
_SIGNATURE_LEN = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN
_SIGNATURE_TIMESTAMP = struct.Struct("<IH")  # 48 bits after the link id


def signing_timestamp(unix_s: float | None = None) -> int:
    """The MAVLink signing timestamp of a Unix time (now by default)."""
    now_s = time.time() if unix_s is None else unix_s
    return max(0, int((now_s - SIGNING_EPOCH_UNIX_S) * SIGNING_TICKS_PER_S))


def new_key() -> bytes:
    return secrets.token_bytes(SIGNING_KEY_BYTES)


class SigningKeyError(ValueError):
    """The key file cannot be read or holds no 32-byte key; the message never shows it."""


class SigningKeyStore:
    """The server's signing key in a file (64 hex digits, or 32 raw bytes) and the
    highest timestamp handed out, in ``<key file>.timestamp`` next to it."""

    def __init__(self, key_file: Path) -> None:
        self.key_file = key_file
        self.lock = asyncio.Lock()  # one provisioning at a time
        self.timestamp_file = key_file.with_name(key_file.name + ".timestamp")
        self.key: bytes | None = _read_key(key_file)
        self.persisted_timestamp = _read_timestamp(self.timestamp_file)

    def start_timestamp(self) -> int:
        """Where signing resumes: past everything persisted, and not behind the clock."""
        return max(self.persisted_timestamp, signing_timestamp())

    def replace_key(self, key: bytes | None) -> None:
        """Write the new key (None: delete the file), atomically and owner-only."""
        if key is None:
            self.key_file.unlink(missing_ok=True)
        else:
            _write_private(self.key_file, key.hex().encode() + b"\n")
        self.key = key

    def checkpoint(self, timestamp: int) -> None:
        """Persist ``timestamp`` + margin unless a higher value is already stored."""
        target = timestamp + PERSIST_MARGIN_TICKS
        if target <= self.persisted_timestamp:
            return
        try:
            # no fsync: it runs on the event loop, and a disk under load can hold an fsync
            # for seconds; a timestamp lost to a power cut leaves the clock to go by
            _write_private(self.timestamp_file, f"{target}\n".encode(), sync=False)
        except OSError as exc:
            log.warning("cannot persist the signing timestamp in %s: %s", self.timestamp_file,
                        exc.strerror)
            return
        self.persisted_timestamp = target


def _read_key(path: Path) -> bytes | None:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise SigningKeyError(f"cannot read signing key file {path}: {exc.strerror}") from None
    text = data.strip()
    if len(data) == SIGNING_KEY_BYTES and len(text) != 2 * SIGNING_KEY_BYTES:
        return data
    try:
        key = bytes.fromhex(text.decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        key = b""
    if len(key) != SIGNING_KEY_BYTES:
        raise SigningKeyError(
            f"signing key file {path} must hold 32 bytes: 64 hex digits or the raw bytes"
        )
    return key


def _read_timestamp(path: Path) -> int:
    try:
        return max(0, int(path.read_text().strip()))
    except (OSError, ValueError):
        return 0


def _write_private(path: Path, data: bytes, *, sync: bool = True) -> None:
    """Write via a temporary file and rename, mode 0600, so a crash leaves old or new."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.write(fd, data)
        if sync:
            os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(temporary, path)


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
        self._unsigned_in = 0
        self._rejected_bad_signature = 0
        self._rejected_replay = 0
        self._rejected_unsigned = 0
        self._provisions = 0
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
        state = self.state
        ids = list(sysids)
        rejected = self._rejected_bad_signature + self._rejected_replay + self._rejected_unsigned
        return SigningStats(
            enabled=self.enabled,
            vehicles_signed=self.enabled and bool(ids) and all(map(self.vehicle_signed, ids)),
            signed_in=state.goodsig_count,
            unsigned_in=self._unsigned_in,
            rejected=rejected,
            rejected_bad_signature=self._rejected_bad_signature,
            rejected_replay=self._rejected_replay,
            rejected_unsigned=self._rejected_unsigned,
            provisions=self._provisions,
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
            self._rejected_unsigned += 1
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
            self._unsigned_in += 1  # with a key, the allowlist callback counted it

    # -- called by the codec while it decodes --
    def verified(self, src_system: int) -> None:
        self._last_verified_s[src_system] = self._clock()

    def failed(self, replay: bool) -> None:
        self._signature_failed = True
        if replay:
            self._rejected_replay += 1
        else:
            self._rejected_bad_signature += 1

    def _accept_unsigned(self, _mav: Any, msg_id: int) -> bool:
        # pymavlink asks this for unsigned frames and for frames whose signature failed
        # (those are already counted by the codec): only the allowlist passes.
        if self._signature_failed:
            self._signature_failed = False
            return False
        if msg_id in UNSIGNED_ALLOWLIST:
            self._unsigned_in += 1
            return True
        self._rejected_unsigned += 1
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
        self._provisions += 1


class SigningLink(Protocol):
    """What :func:`provision` needs of a link."""

    signing: LinkSigning
    mav: mavlink.MAVLink

    def send(self, msg: mavlink.MAVLink_message) -> None: ...


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
    signing = link.signing
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    answered = signing.vehicle_signed if signed else signing.vehicle_unsigned
    while loop.time() < deadline:
        if all(answered(sysid) for sysid in sysids):
            return True
        await asyncio.sleep(0.02)
    return False
