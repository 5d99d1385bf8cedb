"""Component metadata over MAVLink FTP as PX4 serves it: COMPONENT_METADATA names the
general metadata file, which lists the events file; both xz-compressed with MAVLink CRC32s."""

from __future__ import annotations

import json
import lzma
import struct
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from sim.mavlink import mavlink_ftp as ftp
from sim.mavlink.component_metadata import mavlink_crc32
from tests.sim.conftest import Harness
from tests.sim.test_events import DISARMED_BY, _payload

MAX_DATA = ftp.MAX_DATA_LENGTH


def _request(h: Harness, opcode: int, *, seq: int = 0, session: int = 0, offset: int = 0,
             size: int = 0, data: bytes = b"") -> list[ftp.FtpPayload]:
    h.gcs.clear()
    payload = ftp.FtpPayload(seq, session, opcode, size or len(data), 0, 0, offset, data).pack()
    h.deliver(mavlink.MAVLink_file_transfer_protocol_message(0, 1, 1, list(payload)), h.gcs)
    return [ftp.FtpPayload.unpack(bytes(m.payload))
            for m in h.gcs.of_type("FILE_TRANSFER_PROTOCOL")]


def _download(h: Harness, path: str, burst: bool) -> bytes:
    opened = _request(h, ftp.CMD_OPEN_FILE_RO, data=path.encode())
    assert opened[0].opcode == ftp.RSP_ACK
    size = struct.unpack("<I", opened[0].data[:4])[0]
    content = b""
    seq = 1
    while len(content) < size:
        if burst:
            packets = _request(h, ftp.CMD_BURST_READ_FILE, seq=seq, offset=len(content))
            for packet in packets:
                if packet.opcode == ftp.RSP_ACK:
                    assert packet.offset == len(content)
                    content += packet.data[:packet.size]
            seq = packets[-1].seq_number + 1
        else:
            (packet,) = _request(h, ftp.CMD_READ_FILE, seq=seq, offset=len(content),
                                 size=MAX_DATA)
            content += packet.data[:packet.size]
            seq += 2
    (closed,) = _request(h, ftp.CMD_TERMINATE_SESSION, seq=seq)
    assert closed.opcode == ftp.RSP_ACK
    return content


def _component_metadata(h: Harness) -> tuple[int, str]:
    h.gcs.clear()
    h.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, 397, link=h.gcs)
    payloads = [p for m in h.gcs.sent if (p := _payload(m, 397)) is not None]
    assert len(payloads) == 1
    _time, crc, uri = struct.unpack("<II100s", payloads[0].ljust(108, b"\0"))
    return crc, uri.rstrip(b"\0").decode()


def test_general_metadata_and_events_file_download_with_matching_crcs(harness: Harness) -> None:
    crc, uri = _component_metadata(harness)
    assert uri == "mftp://etc/extras/component_general.json.xz"
    general_json = lzma.decompress(_download(harness, uri.removeprefix("mftp://"), burst=True))
    assert mavlink_crc32(general_json) == crc
    # PX4 lists its parameter metadata first, then the events
    parameters_type, events_type = json.loads(general_json)["metadataTypes"]
    assert parameters_type["type"] == 1  # COMP_METADATA_TYPE_PARAMETER
    assert events_type["type"] == 4  # COMP_METADATA_TYPE_EVENTS
    assert events_type["uri"] == "mftp://etc/extras/all_events.json.xz"
    path = events_type["uri"].removeprefix("mftp://")
    events_json = lzma.decompress(_download(harness, path, burst=False))
    assert mavlink_crc32(events_json) == events_type["fileCrc"]
    px4 = json.loads(events_json)["components"]["1"]
    assert px4["namespace"] == "px4"
    disarmed = px4["event_groups"]["default"]["events"][str(DISARMED_BY & 0xFFFFFF)]
    assert disarmed["message"] == "Disarmed by {1}"


def test_parameter_metadata_is_px4s_for_every_parameter_the_vehicle_has(
    harness: Harness,
) -> None:
    _crc, uri = _component_metadata(harness)
    general_json = lzma.decompress(_download(harness, uri.removeprefix("mftp://"), burst=True))
    (parameters_type,) = [t for t in json.loads(general_json)["metadataTypes"] if t["type"] == 1]
    assert parameters_type["uri"] == "mftp://etc/extras/parameters.json.xz"
    path = parameters_type["uri"].removeprefix("mftp://")
    metadata_json = lzma.decompress(_download(harness, path, burst=True))
    assert mavlink_crc32(metadata_json) == parameters_type["fileCrc"]
    by_name = {p["name"]: p for p in json.loads(metadata_json)["parameters"]}
    land_speed = by_name["MPC_LAND_SPEED"]
    assert (land_speed["type"], land_speed["units"], land_speed["min"]) == ("Float", "m/s", 0.6)
    assert land_speed["shortDesc"]
    assert by_name["COM_RC_IN_MODE"]["type"] == "Int32"
    assert "values" in by_name["COM_RC_IN_MODE"]
    # the point-mass harness has the quad's parameters; every one is described
    assert set(harness.vehicle.params) <= set(by_name)


def test_component_information_names_the_same_file(harness: Harness) -> None:
    crc, uri = _component_metadata(harness)
    harness.gcs.clear()
    harness.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, 395, link=harness.gcs)
    (payload,) = [p for m in harness.gcs.sent if (p := _payload(m, 395)) is not None]
    fields: Any = struct.unpack("<III100s100s", payload.ljust(212, b"\0"))
    assert fields[1] == crc
    assert fields[3].rstrip(b"\0").decode() == uri


def test_naks_as_px4(harness: Harness) -> None:
    (missing,) = _request(harness, ftp.CMD_OPEN_FILE_RO, data=b"etc/extras/nothing.json")
    assert (missing.opcode, missing.req_opcode, missing.data[0]) == (
        ftp.RSP_NAK, ftp.CMD_OPEN_FILE_RO, ftp.ERR_FILE_NOT_FOUND)
    (no_session,) = _request(harness, ftp.CMD_READ_FILE, seq=2, size=10)
    assert no_session.data[0] == ftp.ERR_INVALID_SESSION
    path = b"etc/extras/component_general.json.xz"
    _request(harness, ftp.CMD_OPEN_FILE_RO, seq=4, data=path)
    (second,) = _request(harness, ftp.CMD_OPEN_FILE_RO, seq=6, data=path)
    assert second.data[0] == ftp.ERR_NO_SESSIONS_AVAILABLE
    (past_end,) = _request(harness, ftp.CMD_READ_FILE, seq=8, offset=10**6, size=10)
    assert past_end.data[0] == ftp.ERR_EOF
    (unknown,) = _request(harness, 99, seq=10)
    assert unknown.data[0] == ftp.ERR_UNKNOWN_COMMAND
    (reset,) = _request(harness, ftp.CMD_RESET_SESSIONS, seq=12)
    assert reset.opcode == ftp.RSP_ACK
    (closed,) = _request(harness, ftp.CMD_TERMINATE_SESSION, seq=14)
    assert closed.data[0] == ftp.ERR_INVALID_SESSION  # nothing open (seen on PX4 v1.16 SITL)


def test_a_repeated_request_gets_the_same_reply(harness: Harness) -> None:
    path = b"etc/extras/component_general.json.xz"
    (first,) = _request(harness, ftp.CMD_OPEN_FILE_RO, seq=7, data=path)
    (again,) = _request(harness, ftp.CMD_OPEN_FILE_RO, seq=7, data=path)
    assert again == first  # not "no sessions available": the ack was lost, not the request


def test_list_directory(harness: Harness) -> None:
    (listing,) = _request(harness, ftp.CMD_LIST_DIRECTORY, data=b"etc/extras")
    entries = listing.data[:listing.size].split(b"\0")
    names = [e.split(b"\t")[0] for e in entries if e]
    assert names == [
        b"Fall_events.json.xz", b"Fcomponent_general.json.xz", b"Fparameters.json.xz"]
    (end,) = _request(harness, ftp.CMD_LIST_DIRECTORY, seq=2, offset=3, data=b"etc/extras")
    assert end.data[0] == ftp.ERR_EOF
