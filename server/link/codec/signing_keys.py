"""The server's MAVLink signing key in its file, and the signing timestamp kept beside it."""

from __future__ import annotations

import asyncio
import logging
import os
import secrets
import time
from pathlib import Path

log = logging.getLogger(__name__)

SIGNING_KEY_BYTES = 32
# MAVLink signing timestamps count 10 µs since 2015-01-01T00:00:00Z.
SIGNING_EPOCH_UNIX_S = 1_420_070_400
SIGNING_TICKS_PER_S = 100_000
# The persisted timestamp runs this far ahead of the one in use, so frames signed after
# the last write (a crash) still lie below what a restart starts from: 60 s of ticks, far
# more than a link can sign between two writes (one tick per frame).
PERSIST_MARGIN_TICKS = 60 * SIGNING_TICKS_PER_S


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
