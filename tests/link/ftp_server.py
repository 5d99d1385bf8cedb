"""A MAVLink FTP server as PX4's mavlink_ftp answers, for a ScriptedPeer: one session,
sequence number + 1 in every reply, the last reply re-sent for a repeated request, NAKs
with PX4's error codes. ``drop_every`` loses every n-th reply once, as a lossy radio would."""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import development as mavlink

from server.link.plugins.ftp import (
    FTP_DATA_LEN,
    decode_payload,
    encode_payload,
    kCmdBurstReadFile,
    kCmdOpenFileRO,
    kCmdReadFile,
    kCmdResetSessions,
    kCmdTerminateSession,
    kErrEOF,
    kErrNoSessionsAvailable,
    kRspAck,
    kRspNak,
)
from tests.link.conftest import ScriptedPeer

kErrInvalidSession = 4
kErrUnknownCommand = 7
kErrFileNotFound = 10


class FtpServer:
    def __init__(self, peer: ScriptedPeer, files: dict[str, bytes]) -> None:
        self.peer = peer
        self.files = files
        self.session_open = False
        self.reads = 0  # ReadFile requests executed (not re-sent answers)
        self.requests = 0
        self.drop_every = 0
        self.burst_packets = 0  # packets per BurstReadFile; 0: the command is unknown
        self.bursts = 0
        self._file = b""
        self._last: tuple[int, list[int]] | None = None  # (request seq, reply payload)
        self._replies = 0

    def handle(self, msg: mavlink.MAVLink_message) -> None:
        if msg.get_type() != "FILE_TRANSFER_PROTOCOL":
            return
        self.requests += 1
        req = decode_payload(msg.payload)
        if req.opcode == kCmdBurstReadFile and self.burst_packets and self.session_open:
            self._stream(req.seq_number, req.offset)
            return
        if self._last is not None and self._last[0] == req.seq_number:
            self._send(self._last[1])  # its answer got lost: the same answer again
            return
        opcode, data, session, offset = self._work(req.opcode, req.session, req.offset, msg)
        payload = encode_payload(req.seq_number + 1, session, opcode, offset, data)
        payload[5] = req.opcode  # req_opcode
        self._last = (req.seq_number, payload)
        self._send(payload)

    def _work(
        self, opcode: int, session: int, offset: int, msg: mavlink.MAVLink_message
    ) -> tuple[int, bytes, int, int]:
        req = decode_payload(msg.payload)
        if opcode == kCmdOpenFileRO:
            path = req.data.decode()
            if self.session_open:
                return kRspNak, bytes([kErrNoSessionsAvailable]), 0, 0
            if path not in self.files:
                return kRspNak, bytes([kErrFileNotFound]), 0, 0
            self.session_open, self._file = True, self.files[path]
            return kRspAck, struct.pack("<I", len(self._file)), 0, 0
        if opcode == kCmdReadFile:
            if not self.session_open:
                return kRspNak, bytes([kErrInvalidSession]), session, offset
            self.reads += 1
            if offset >= len(self._file):
                return kRspNak, bytes([kErrEOF]), session, offset
            return kRspAck, self._file[offset : offset + FTP_DATA_LEN], session, offset
        if opcode in (kCmdTerminateSession, kCmdResetSessions):
            self.session_open = False
            return kRspAck, b"", session, 0
        return kRspNak, bytes([kErrUnknownCommand]), session, offset

    def _stream(self, seq: int, offset: int) -> None:
        """PX4's _workBurst: ACKs from offset, the last of a burst flagged complete; NAK
        EOF past the end."""
        self.bursts += 1
        for i in range(self.burst_packets):
            seq = (seq + 1) & 0xFFFF
            if offset >= len(self._file):
                payload = encode_payload(seq, 0, kRspNak, offset, bytes([kErrEOF]))
                payload[5] = kCmdBurstReadFile
                self._send(payload)
                return
            chunk = self._file[offset : offset + FTP_DATA_LEN]
            payload = encode_payload(seq, 0, kRspAck, offset, chunk)
            payload[5] = kCmdBurstReadFile
            payload[6] = int(i == self.burst_packets - 1)  # burst_complete
            self._send(payload)
            offset += len(chunk)

    def _send(self, payload: list[int]) -> None:
        self._replies += 1
        if self.drop_every and self._replies % self.drop_every == 0:
            return
        self.peer.send(mavlink.MAVLink_file_transfer_protocol_message(0, 255, 190, payload))
