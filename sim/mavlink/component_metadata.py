"""Component metadata as PX4 v1.16 serves it: COMPONENT_METADATA / COMPONENT_INFORMATION on
MAV_CMD_REQUEST_MESSAGE name the general metadata file, which lists the parameter metadata
(PX4's own for every parameter the sim has: type, default, range, unit, descriptions, enum
values; sim/data/px4_parameters.json) and the events metadata; all are xz-compressed JSON read
over MAVLink FTP (`sim.mavlink.mavlink_ftp`).

PX4 builds these files at compile time (generate_component_general.py): each fileCrc is
MAVLink's CRC32 (reflected 0xEDB88320, start 0, no final inversion) of the uncompressed JSON.
"""

from __future__ import annotations

import json
import lzma
import struct
import zlib
from importlib import resources

from sim.lib.mavlink_custom import CustomMessage

MAVLINK_MSG_ID_COMPONENT_INFORMATION = 395
MAVLINK_MSG_ID_COMPONENT_METADATA = 397
COMP_METADATA_TYPE_PARAMETER = 1
COMP_METADATA_TYPE_EVENTS = 4

GENERAL_METADATA_PATH = "etc/extras/component_general.json.xz"
PARAMETER_METADATA_PATH = "etc/extras/parameters.json.xz"
EVENTS_METADATA_PATH = "etc/extras/all_events.json.xz"
URI_MAX_LEN = 100


class ComponentMetadataMessage(CustomMessage):
    id = MAVLINK_MSG_ID_COMPONENT_METADATA
    msgname = "COMPONENT_METADATA"
    crc_extra = 182
    fieldnames = ("time_boot_ms", "file_crc", "uri")
    _wire = struct.Struct("<II100s")


class ComponentInformationMessage(CustomMessage):
    id = MAVLINK_MSG_ID_COMPONENT_INFORMATION
    msgname = "COMPONENT_INFORMATION"
    crc_extra = 0
    fieldnames = ("time_boot_ms", "general_metadata_file_crc", "peripherals_metadata_file_crc",
                  "general_metadata_uri", "peripherals_metadata_uri")
    _wire = struct.Struct("<III100s100s")


def mavlink_crc32(data: bytes) -> int:
    """MAVLink's CRC32 as PX4's metadata generator computes fileCrc (no pre/post inversion)."""
    return ~zlib.crc32(data, 0xFFFFFFFF) & 0xFFFFFFFF


def _xz(data: bytes) -> bytes:
    return lzma.compress(data, format=lzma.FORMAT_XZ, preset=9)


class ComponentMetadata:
    """The files served over FTP and the messages that point at them."""

    def __init__(self) -> None:
        data = resources.files("sim").joinpath("data")
        events_json = data.joinpath("px4_events.json").read_bytes()
        parameters_json = data.joinpath("px4_parameters.json").read_bytes()
        general = {
            "metadataTypes": [{
                "fileCrc": mavlink_crc32(parameters_json),
                "type": COMP_METADATA_TYPE_PARAMETER,
                "uri": "mftp://" + PARAMETER_METADATA_PATH,
            }, {
                "fileCrc": mavlink_crc32(events_json),
                "type": COMP_METADATA_TYPE_EVENTS,
                "uri": "mftp://" + EVENTS_METADATA_PATH,
            }],
            "version": 1,
        }
        general_json = json.dumps(general, sort_keys=True).encode()
        self.general_crc = mavlink_crc32(general_json)
        self.general_uri = "mftp://" + GENERAL_METADATA_PATH
        self.files: dict[str, bytes] = {
            GENERAL_METADATA_PATH: _xz(general_json),
            PARAMETER_METADATA_PATH: _xz(parameters_json),
            EVENTS_METADATA_PATH: _xz(events_json),
        }

    def build(self, msg_id: int, time_boot_ms: int) -> CustomMessage | None:
        uri = self.general_uri.encode()
        if msg_id == MAVLINK_MSG_ID_COMPONENT_METADATA:
            return ComponentMetadataMessage(time_boot_ms, self.general_crc, uri)
        if msg_id == MAVLINK_MSG_ID_COMPONENT_INFORMATION:
            return ComponentInformationMessage(time_boot_ms, self.general_crc, 0, uri, b"")
        return None


_SHARED: ComponentMetadata | None = None


def shared() -> ComponentMetadata:
    """One compressed copy for every vehicle in the process (compressing takes ~0.1 s)."""
    global _SHARED
    if _SHARED is None:
        _SHARED = ComponentMetadata()
    return _SHARED
