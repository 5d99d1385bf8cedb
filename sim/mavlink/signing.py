"""MAVLink 2 message signing of the simulated vehicle, as PX4's main branch does it.

PX4 v1.16 (the release the sim otherwise matches) has no signing; it came later
(``src/modules/mavlink/mavlink_sign_control.cpp`` and ``mavlink_signing_storage.cpp``,
docs page "MAVLink Message Signing"). Like that code:

- The key lives in a 40-byte file per vehicle, ``mavlink/mavlink-signing-key.bin`` under
  the instance's directory: 32 bytes of key, then the timestamp (uint64, little-endian),
  mode 0600 in a 0700 directory. A non-zero key or timestamp there switches signing on at
  start, with the timestamp not behind the clock.
- SETUP_SIGNING sets, changes or (all-zero key and timestamp) removes the key, on any
  link, when broadcast or addressed to this vehicle, and never while armed. Once a key is
  set, only a SETUP_SIGNING signed with it gets through (unsigned ones are rejected like
  any other unsigned message). The file is rewritten, and again at a graceful stop.
- With a key, everything the vehicle sends is signed, and unsigned or badly signed frames
  are dropped before anything handles them, except HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE
  and COLLISION. Without a key, nothing is signed and everything is accepted.

pymavlink does the HMAC and the replay window (per stream: link id, system, component).
"""

from __future__ import annotations

import logging
import os
import struct
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

log = logging.getLogger(__name__)

MAVLINK_SECRET_FILE = Path("mavlink") / "mavlink-signing-key.bin"
MAVLINK_SECRET_KEY_LENGTH = 32
MAVLINK_MSG_ID_SETUP_SIGNING = mavlink.MAVLINK_MSG_ID_SETUP_SIGNING
UNSIGNED_ALLOWLIST = frozenset(
    {
        mavlink.MAVLINK_MSG_ID_HEARTBEAT,
        mavlink.MAVLINK_MSG_ID_RADIO_STATUS,
        mavlink.MAVLINK_MSG_ID_ADSB_VEHICLE,
        mavlink.MAVLINK_MSG_ID_COLLISION,
    }
)
# MAVLink signing timestamps count 10 µs since 2015-01-01T00:00:00Z.
_UNIX_EPOCH_OFFSET_S = 1_420_070_400
_TICKS_PER_S = 100_000
_TIMESTAMP = struct.Struct("<Q")
_SIGNATURE_LEN = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN


def system_timestamp() -> int:
    return max(0, int((time.time() - _UNIX_EPOCH_OFFSET_S) * _TICKS_PER_S))


class VehicleSigning:
    """One vehicle's key and the signing state of each of its links."""

    def __init__(
        self,
        key_file: Path | None,
        *,
        sysid: int,
        compid: int,
        is_armed: Callable[[], bool],
    ) -> None:
        self.key_file = key_file
        self.sysid = sysid
        self.compid = compid
        self._is_armed = is_armed
        self.secret_key: bytes | None = None
        self.rejected = 0  # frames dropped: unsigned, bad signature or replayed
        self.setup_refused = 0  # SETUP_SIGNING ignored (armed, or addressed to another)
        self._states: list[mavlink.MAVLinkSigning] = []
        timestamp = 0
        if key_file is not None:
            key, timestamp = _load(key_file)
            if key != bytes(MAVLINK_SECRET_KEY_LENGTH) or timestamp != 0:
                self.secret_key = key
                log.info("vehicle %d: MAVLink signing key loaded", sysid)
        self._timestamp = max(timestamp, system_timestamp()) if self.secret_key else 0

    @property
    def enabled(self) -> bool:
        return self.secret_key is not None

    def codec(self, link_id: int) -> mavlink.MAVLink:
        """A pymavlink codec for one link, signing and checking with this vehicle's key."""
        state = mavlink.MAVLinkSigning()
        state.link_id = link_id % 256
        state.allow_unsigned_callback = self._accept_unsigned
        self._apply(state, self._timestamp)
        self._states.append(state)
        return _VehicleCodec(state, self.sysid, self.compid)

    def handle_setup_signing(self, msg: Any) -> bool:
        """Apply a SETUP_SIGNING that got through the link's checks; True when applied."""
        if msg.target_system not in (0, self.sysid) or msg.target_component not in (
            0, self.compid,
        ):  # fmt: skip
            self.setup_refused += 1
            return False
        if self._is_armed():
            self.setup_refused += 1
            log.info("vehicle %d: SETUP_SIGNING rejected while armed", self.sysid)
            return False
        key = bytes(msg.secret_key)
        timestamp = int(msg.initial_timestamp)
        if key == bytes(MAVLINK_SECRET_KEY_LENGTH) and timestamp == 0:
            self.secret_key = None
            log.info("vehicle %d: MAVLink signing key cleared via SETUP_SIGNING", self.sysid)
        else:
            self.secret_key = key
            log.info("vehicle %d: MAVLink signing key updated via SETUP_SIGNING", self.sysid)
        self._timestamp = timestamp
        for state in self._states:
            state.stream_timestamps.clear()
            self._apply(state, timestamp)
            state.timestamp = timestamp
        self._write()
        return True

    def close(self) -> None:
        """A graceful stop writes the timestamp reached back to the file."""
        if self.enabled:
            self._timestamp = max([self._timestamp, *(s.timestamp for s in self._states)])
            self._write()

    def _apply(self, state: mavlink.MAVLinkSigning, timestamp: int) -> None:
        state.secret_key = self.secret_key
        state.sign_outgoing = self.secret_key is not None
        state.timestamp = max(state.timestamp, timestamp)

    def _accept_unsigned(self, _mav: Any, msg_id: int) -> bool:
        # asked for unsigned frames and for those whose signature failed
        if msg_id in UNSIGNED_ALLOWLIST:
            return True
        self.rejected += 1
        return False

    def _write(self) -> None:
        if self.key_file is None:
            return
        data = (self.secret_key or bytes(MAVLINK_SECRET_KEY_LENGTH)) + _TIMESTAMP.pack(
            self._timestamp if self.secret_key else 0
        )
        try:
            self.key_file.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
            fd = os.open(self.key_file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            try:
                os.write(fd, data)
            finally:
                os.close(fd)
        except OSError as exc:
            log.error("vehicle %d: cannot write %s: %s", self.sysid, self.key_file, exc.strerror)


def _load(path: Path) -> tuple[bytes, int]:
    """The key and timestamp of a key file; zeros when it is missing or short."""
    try:
        data = path.read_bytes()
    except OSError:
        return bytes(MAVLINK_SECRET_KEY_LENGTH), 0
    if len(data) < MAVLINK_SECRET_KEY_LENGTH + _TIMESTAMP.size:
        return bytes(MAVLINK_SECRET_KEY_LENGTH), 0
    (timestamp,) = _TIMESTAMP.unpack_from(data, MAVLINK_SECRET_KEY_LENGTH)
    return data[:MAVLINK_SECRET_KEY_LENGTH], int(timestamp)


class _VehicleCodec(mavlink.MAVLink):  # type: ignore[misc]  # pymavlink is untyped
    """pymavlink's codec with MAVLink's C-library order: a stream's timestamp moves only
    when the signature is good (pymavlink records it first, so one forged frame with a
    far-future timestamp would make every genuine frame of the stream a "replay")."""

    def __init__(self, state: mavlink.MAVLinkSigning, sysid: int, compid: int) -> None:
        super().__init__(None, srcSystem=sysid, srcComponent=compid)
        self.robust_parsing = True
        self.signing = state

    def check_signature(self, msgbuf: bytearray, srcSystem: int, srcComponent: int) -> bool:
        stream = (msgbuf[-_SIGNATURE_LEN], srcSystem, srcComponent)
        streams = self.signing.stream_timestamps
        before = streams.get(stream)
        if super().check_signature(msgbuf, srcSystem, srcComponent) is True:
            return True
        if before is None:
            streams.pop(stream, None)
        else:
            streams[stream] = before
        return False
