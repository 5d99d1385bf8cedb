"""Component metadata as PX4 serves it: which files describe the vehicle's parameters,
events, actuators, where they are (mftp:// over MAVLink FTP) and their CRCs.

Discovery follows QGroundControl: MAV_CMD_REQUEST_MESSAGE(COMPONENT_METADATA), falling back
to COMPONENT_INFORMATION for older firmware; the general metadata file it names lists each
metadata type's uri and fileCrc. Files ending in .xz are xz-compressed. The CRC is MAVLink's
CRC32 (PX4's generate_crc.py): PX4 v1.16 computes COMPONENT_METADATA's over the general
JSON before compression, and the listed files' over the .xz as stored.

A downloaded events or parameters file is cached per firmware (AUTOPILOT_VERSION's
flight_sw_version) and general-metadata CRC, so a reconnect costs two small requests instead
of a download.
"""

from __future__ import annotations

import json
import logging
import lzma
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec.px4_messages import (
    MAVLINK_MSG_ID_COMPONENT_INFORMATION,
    MAVLINK_MSG_ID_COMPONENT_METADATA,
    text_field,
)
from server.link.core.vehicle_core import VehicleCore
from server.link.plugins.ftp import FtpClient, FtpError

log = logging.getLogger(__name__)

COMP_METADATA_TYPE_PARAMETER = 1
COMP_METADATA_TYPE_EVENTS = 4
MAV_CMD_REQUEST_MESSAGE = 512
_MFTP = "mftp://"


def _crc32_table() -> list[int]:
    table = []
    for i in range(256):
        k = i
        for _ in range(8):
            k = (k >> 1) ^ 0xEDB88320 if k & 1 else k >> 1
        table.append(k)
    return table


_CRC32_TABLE = _crc32_table()


def mavlink_crc32(data: bytes, crc: int = 0) -> int:
    """MAVLink's CRC32 (reflected 0xEDB88320, starting at 0, no final inversion)."""
    for byte in data:
        crc = (crc >> 8) ^ _CRC32_TABLE[(crc ^ byte) & 0xFF]
    return crc


def default_cache_dir() -> Path:
    """$SKYHELM_CACHE_DIR, else $XDG_CACHE_HOME/skyhelm (~/.cache/skyhelm)."""
    if chosen := os.environ.get("SKYHELM_CACHE_DIR"):
        return Path(chosen)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "skyhelm"


def mftp_path(uri: str) -> str | None:
    """The FTP path of an mftp:// uri (a "[;comp=N]" prefix names another component and is
    dropped: the autopilot serves its own); None for any other scheme."""
    if not uri.startswith(_MFTP):
        return None
    path = uri[len(_MFTP) :]
    if path.startswith("[;comp="):
        path = path.partition("]")[2]
    return path


class MetadataError(Exception):
    """The vehicle's metadata could not be found, fetched or trusted."""


class ComponentMetadata:
    """Finds, downloads, checks and caches a vehicle's events and parameters metadata."""

    answer_timeout_s = 1.0

    def __init__(self, core: VehicleCore, ftp: FtpClient, cache_dir: Path | None = None) -> None:
        self._core = core
        self._ftp = ftp
        self.cache_dir = cache_dir
        self.flight_sw_version: int | None = None
        self._general: tuple[str, int] | None = None  # (uri, file_crc)
        core.on_message("AUTOPILOT_VERSION", self._on_autopilot_version)
        core.on_message("COMPONENT_METADATA", self._on_component_metadata)
        core.on_message("COMPONENT_INFORMATION", self._on_component_information)

    def _on_autopilot_version(self, msg: mavlink.MAVLink_autopilot_version_message) -> None:
        self.flight_sw_version = msg.flight_sw_version

    def _on_component_metadata(self, msg: Any) -> None:
        self._general = (text_field(msg.uri), msg.file_crc)

    def _on_component_information(self, msg: Any) -> None:
        if self._general is None:
            self._general = (text_field(msg.general_metadata_uri), msg.general_metadata_file_crc)

    async def events(self) -> dict[str, Any]:
        """The vehicle's events definitions (PX4's events JSON), from cache or the vehicle."""
        return await self._metadata(COMP_METADATA_TYPE_EVENTS, "px4_events")

    async def parameters(self) -> dict[str, Any]:
        """The vehicle's parameter definitions (PX4's parameters.json: each parameter's
        group, descriptions, units, range and default), from cache or the vehicle."""
        return await self._metadata(COMP_METADATA_TYPE_PARAMETER, "px4_parameters")

    async def _metadata(self, metadata_type: int, cache_name: str) -> dict[str, Any]:
        """One metadata file the general metadata lists, cached per firmware and general
        metadata CRC under cache_name."""
        await self._ask(
            mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION, lambda: self.flight_sw_version is not None
        )

        def known() -> bool:
            return self._general is not None

        if not await self._ask(MAVLINK_MSG_ID_COMPONENT_METADATA, known):
            await self._ask(MAVLINK_MSG_ID_COMPONENT_INFORMATION, known)
        if self._general is None:
            raise MetadataError("the vehicle offers no component metadata")
        uri, general_crc = self._general
        cached = self._cache_file(cache_name, general_crc)
        if cached is not None and cached.exists():
            try:
                loaded: dict[str, Any] = json.loads(cached.read_text())
                return loaded
            except (OSError, ValueError):
                log.warning("%s metadata cache %s unreadable: fetching again", cache_name, cached)
        general = json.loads(await self._fetch(uri, general_crc))
        entry = next(
            (t for t in general.get("metadataTypes", []) if t.get("type") == metadata_type),
            None,
        )
        if entry is None:
            raise MetadataError(f"the general metadata lists no file of type {metadata_type}")
        text = await self._fetch(str(entry.get("uri", "")), int(entry.get("fileCrc", 0)))
        parsed: dict[str, Any] = json.loads(text)
        if cached is not None:
            try:
                cached.parent.mkdir(parents=True, exist_ok=True)
                # written whole under another name, then renamed: another process reading
                # the cache never sees half a file
                partial = cached.with_name(f"{cached.name}.{os.getpid()}.partial")
                partial.write_bytes(text)
                partial.replace(cached)
            except OSError:
                log.warning("cannot cache %s metadata in %s", cache_name, cached.parent)
        return parsed

    def _cache_file(self, cache_name: str, general_crc: int) -> Path | None:
        if self.flight_sw_version is None or self.cache_dir is None:
            return None
        name = f"{self.flight_sw_version:08x}_{general_crc:08x}.json"
        return self.cache_dir / cache_name / name

    async def _ask(self, msg_id: int, answered: Callable[[], bool]) -> bool:
        requests = self._core.requests

        def request() -> None:
            self._core.send(self._core.mav.command_long_encode(
                self._core.sysid, self._core.compid, MAV_CMD_REQUEST_MESSAGE, 0,
                msg_id, 0, 0, 0, 0, 0, 0))  # fmt: skip

        return await requests.until(request, answered, self.answer_timeout_s)

    async def _fetch(self, uri: str, file_crc: int) -> bytes:
        path = mftp_path(uri)
        if path is None:
            raise MetadataError(f"not served over MAVLink FTP: {uri}")
        try:
            raw = await self._ftp.download(path)
        except FtpError as e:
            raise MetadataError(f"{uri}: {e}") from e
        data = raw
        if path.endswith(".xz"):
            try:
                data = lzma.decompress(raw)
            except lzma.LZMAError as e:
                raise MetadataError(f"{uri}: {e}") from e
        # PX4 v1.16 gives the general file's CRC over its JSON and the listed files' CRCs
        # over the file as stored (.xz): either matches
        if file_crc and file_crc not in (mavlink_crc32(raw), mavlink_crc32(data)):
            raise MetadataError(f"{uri}: CRC mismatch (expected {file_crc})")
        return data
