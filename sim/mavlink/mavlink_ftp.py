"""A read-only MAVLink FTP server over in-memory files, after PX4's mavlink_ftp.cpp.

PX4 keeps one session per link: OpenFileRO answers the file size, ReadFile and
BurstReadFile send data (a burst streams up to ~35 kB, the last packet flagged
burst_complete, or ends with a NAK EOF), TerminateSession / ResetSessions close it.
A request repeated with the same sequence number gets the last small reply again.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import development as mavlink

from sim.mavlink.vehicle_interface import Link, Message

# PayloadHeader: seq_number, session, opcode, size, req_opcode, burst_complete, padding, offset
_HEADER = struct.Struct("<HBBBBBBI")
FTP_PAYLOAD_LEN = 251
MAX_DATA_LENGTH = FTP_PAYLOAD_LEN - _HEADER.size
# PX4 ends a burst after this many bytes so that other traffic gets through
BURST_CHUNK_BYTES = 35000

CMD_NONE = 0
CMD_TERMINATE_SESSION = 1
CMD_RESET_SESSIONS = 2
CMD_LIST_DIRECTORY = 3
CMD_OPEN_FILE_RO = 4
CMD_READ_FILE = 5
CMD_BURST_READ_FILE = 15
RSP_ACK = 128
RSP_NAK = 129

ERR_NONE = 0
ERR_FAIL = 1
ERR_FAIL_ERRNO = 2
ERR_INVALID_DATA_SIZE = 3
ERR_INVALID_SESSION = 4
ERR_NO_SESSIONS_AVAILABLE = 5
ERR_EOF = 6
ERR_UNKNOWN_COMMAND = 7
ERR_FILE_NOT_FOUND = 10


@dataclass
class FtpPayload:
    seq_number: int
    session: int
    opcode: int
    size: int
    req_opcode: int
    burst_complete: int
    offset: int
    data: bytes = b""

    @classmethod
    def unpack(cls, payload: bytes) -> FtpPayload:
        payload = payload.ljust(FTP_PAYLOAD_LEN, b"\0")
        seq, session, opcode, size, req_opcode, burst, _pad, offset = _HEADER.unpack_from(payload)
        return cls(seq, session, opcode, size, req_opcode, burst, offset,
                   payload[_HEADER.size:_HEADER.size + MAX_DATA_LENGTH])

    def pack(self) -> bytes:
        header = _HEADER.pack(self.seq_number & 0xFFFF, self.session, self.opcode, self.size,
                              self.req_opcode, self.burst_complete, 0, self.offset)
        return (header + self.data[:self.size]).ljust(FTP_PAYLOAD_LEN, b"\0")


@dataclass
class _Session:
    path: str | None = None
    last_reply: Message | None = field(default=None, repr=False)
    last_reply_seq: int = -1


def ftp_message(target_system: int, target_component: int, payload: bytes) -> Message:
    return mavlink.MAVLink_file_transfer_protocol_message(0, target_system, target_component,
                                                          list(payload))


class FtpServer:
    """One session per link, over a fixed set of files keyed by their path."""

    def __init__(self, files: Mapping[str, bytes], sysid: int, compid: int) -> None:
        self._files = files
        self._sysid = sysid
        self._compid = compid
        self._sessions: dict[int, _Session] = {}

    def handle(self, link: Link, msg: Message) -> None:
        if msg.target_system not in (self._sysid, 0) or msg.target_component not in (
                self._compid, 0):
            return
        session = self._sessions.setdefault(id(link), _Session())
        request = FtpPayload.unpack(bytes(msg.payload))
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if session.last_reply is not None and request.seq_number + 1 == session.last_reply_seq:
            link.send(session.last_reply)  # the (n)ack was lost and the request resent
            return
        reply = FtpPayload(request.seq_number + 1, request.session, RSP_ACK, 0, request.opcode, 0,
                           request.offset)
        error = self._work(session, request, reply)
        if error == ERR_NONE and request.opcode == CMD_BURST_READ_FILE:
            session.last_reply = None
            for packet in self._burst(session, request):
                link.send(ftp_message(sysid, compid, packet.pack()))
            return
        if error != ERR_NONE:
            reply.opcode, reply.size, reply.data = RSP_NAK, 1, bytes([error])
        answer = ftp_message(sysid, compid, reply.pack())
        small = reply.size <= 4 and error != ERR_NO_SESSIONS_AVAILABLE
        session.last_reply = answer if small else None
        session.last_reply_seq = reply.seq_number
        link.send(answer)

    def _work(self, session: _Session, request: FtpPayload, reply: FtpPayload) -> int:
        opcode = request.opcode
        if request.size > MAX_DATA_LENGTH:
            return ERR_INVALID_DATA_SIZE
        if opcode == CMD_NONE:
            return ERR_NONE
        if opcode in (CMD_TERMINATE_SESSION, CMD_RESET_SESSIONS):
            if opcode == CMD_TERMINATE_SESSION and (request.session != 0 or session.path is None):
                return ERR_INVALID_SESSION
            session.path = None
            return ERR_NONE
        if opcode == CMD_OPEN_FILE_RO:
            return self._open(session, request, reply)
        if opcode == CMD_READ_FILE:
            return self._read(session, request, reply)
        if opcode == CMD_BURST_READ_FILE:
            return ERR_INVALID_SESSION if session.path is None else ERR_NONE
        if opcode == CMD_LIST_DIRECTORY:
            return self._list(request, reply)
        return ERR_UNKNOWN_COMMAND

    def _open(self, session: _Session, request: FtpPayload, reply: FtpPayload) -> int:
        if session.path is not None:
            return ERR_NO_SESSIONS_AVAILABLE
        path = _path_of(request)
        if path not in self._files:
            return ERR_FILE_NOT_FOUND
        session.path = path
        reply.session = 0
        reply.size = 4
        reply.data = struct.pack("<I", len(self._files[path]))
        return ERR_NONE

    def _read(self, session: _Session, request: FtpPayload, reply: FtpPayload) -> int:
        if request.session != 0 or session.path is None:
            return ERR_INVALID_SESSION
        content = self._files[session.path]
        if request.offset >= len(content):
            return ERR_EOF
        reply.data = content[request.offset:request.offset + request.size]
        reply.size = len(reply.data)
        return ERR_NONE

    def _burst(self, session: _Session, request: FtpPayload) -> list[FtpPayload]:
        content = self._files[session.path or ""]
        packets: list[FtpPayload] = []
        offset, sent, seq = request.offset, 0, request.seq_number + 1
        while True:
            if offset >= len(content):
                packets.append(FtpPayload(seq, 0, RSP_NAK, 1, CMD_BURST_READ_FILE, 0, offset,
                                          bytes([ERR_EOF])))
                return packets
            data = content[offset:offset + MAX_DATA_LENGTH]
            sent += len(data)
            complete = int(sent > BURST_CHUNK_BYTES)
            packets.append(FtpPayload(seq, 0, RSP_ACK, len(data), CMD_BURST_READ_FILE, complete,
                                      offset, data))
            offset += len(data)
            seq += 1
            if complete:
                return packets

    def _list(self, request: FtpPayload, reply: FtpPayload) -> int:
        """Entries of a directory, "F<name>\\t<size>" or "D<name>", NUL separated."""
        directory = _path_of(request).strip("/")
        entries: dict[str, int | None] = {}
        for path, content in self._files.items():
            if not path.startswith(directory + "/") and directory:
                continue
            rest = path[len(directory) + 1:] if directory else path
            name, _, below = rest.partition("/")
            entries[name] = None if below else len(content)
        if not entries and directory not in ("", "."):
            return ERR_FILE_NOT_FOUND
        listed = sorted(entries.items())[request.offset:]
        if not listed:
            return ERR_EOF
        data = b""
        for name, size in listed:
            entry = (f"D{name}" if size is None else f"F{name}\t{size}").encode() + b"\0"
            if len(data) + len(entry) > MAX_DATA_LENGTH:
                break
            data += entry
        reply.data, reply.size = data, len(data)
        return ERR_NONE


def _path_of(request: FtpPayload) -> str:
    return request.data[:request.size].split(b"\0", 1)[0].decode(errors="replace").lstrip("/")
