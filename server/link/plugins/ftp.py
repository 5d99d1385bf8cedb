"""MAVLink FTP (FILE_TRANSFER_PROTOCOL, 110): reading a file off the vehicle as PX4's
mavlink_ftp serves it.

Each request carries a sequence number; PX4 answers with that number + 1 and remembers its
last reply, so a request re-sent with the same number (its answer got lost) is answered
again rather than executed twice. One request is in flight at a time. A read is OpenFileRO
(answered with the file's size), ReadFile at increasing offsets until the size is reached
or PX4 answers NAK EOF, then TerminateSession. PX4 keeps one session: a stale one left by
an earlier client (NAK NoSessionsAvailable) is cleared with ResetSessions.
"""

from __future__ import annotations

import asyncio
import struct
from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import development as mavlink

# PX4's MavlinkFTP::Opcode
kCmdTerminateSession = 1
kCmdResetSessions = 2
kCmdOpenFileRO = 4
kCmdReadFile = 5
kCmdBurstReadFile = 15
kRspAck = 128
kRspNak = 129
# PX4's MavlinkFTP::ErrorCode
FTP_ERROR_NAMES = (
    "None", "Fail", "FailErrno", "InvalidDataSize", "InvalidSession", "NoSessionsAvailable",
    "EOF", "UnknownCommand", "FailFileExists", "FailFileProtected", "FileNotFound",
)  # fmt: skip
kErrNoSessionsAvailable = 5
kErrEOF = 6
kErrUnknownCommand = 7

_HEADER = struct.Struct("<HBBBBBBI")  # seq_number session opcode size req_opcode burst pad offset
FTP_PAYLOAD_LEN = 251
FTP_DATA_LEN = FTP_PAYLOAD_LEN - _HEADER.size  # 239


class FtpError(Exception):
    """The vehicle refused (NAK) or never answered an FTP request."""

    def __init__(self, opcode: int, error: str) -> None:
        super().__init__(f"FTP opcode {opcode}: {error}")
        self.opcode = opcode
        self.error = error


@dataclass(frozen=True)
class FtpReply:
    seq_number: int
    session: int
    opcode: int
    req_opcode: int
    offset: int
    data: bytes
    burst_complete: bool = False
    error: int = 0  # a NAK's error code (PX4's ErrorCode)


def encode_payload(
    seq: int, session: int, opcode: int, offset: int, data: bytes = b"", size: int | None = None
) -> list[int]:
    """The 251 payload bytes of one FTP message."""
    size = len(data) if size is None else size
    header = _HEADER.pack(seq & 0xFFFF, session, opcode, size, 0, 0, 0, offset)
    return list((header + data).ljust(FTP_PAYLOAD_LEN, b"\0"))


def decode_payload(payload: bytes | list[int]) -> FtpReply:
    raw = bytes(payload).ljust(FTP_PAYLOAD_LEN, b"\0")
    seq, session, opcode, size, req_opcode, burst, _pad, offset = _HEADER.unpack_from(raw)
    data = raw[_HEADER.size : _HEADER.size + min(size, FTP_DATA_LEN)]
    error = data[0] if opcode == kRspNak and data else 0
    return FtpReply(seq, session, opcode, req_opcode, offset, data, bool(burst), error)


class FtpClient:
    """Downloads files from one vehicle component over its send path."""

    timeout_s = 0.5  # per try
    retries = 5

    def __init__(
        self,
        *,
        send: Callable[[mavlink.MAVLink_message], None],
        mav: mavlink.MAVLink,
        target: tuple[int, int],
    ) -> None:
        self._send = send
        self._mav = mav
        self._target = target
        self._seq = 0
        self._lock = asyncio.Lock()
        self._waiting: tuple[int, asyncio.Future[FtpReply]] | None = None
        self._burst: asyncio.Queue[FtpReply] | None = None

    def handle_message(self, msg: mavlink.MAVLink_file_transfer_protocol_message) -> None:
        if msg.target_system not in (0, self._mav.srcSystem):
            return
        reply = decode_payload(msg.payload)
        if self._burst is not None and reply.req_opcode == kCmdBurstReadFile:
            self._burst.put_nowait(reply)
            return
        if self._waiting is None:
            return
        expected_seq, future = self._waiting
        if reply.seq_number == expected_seq and not future.done():
            future.set_result(reply)

    async def download(self, path: str) -> bytes:
        """The whole file at ``path`` (relative to PX4's FTP root, as in an mftp:// URI)."""
        async with self._lock:
            try:
                opened = await self._request(kCmdOpenFileRO, data=path.encode())
            except FtpError as e:
                if e.error != FTP_ERROR_NAMES[kErrNoSessionsAvailable]:
                    raise
                await self._request(kCmdResetSessions)
                opened = await self._request(kCmdOpenFileRO, data=path.encode())
            (size,) = struct.unpack_from("<I", opened.data.ljust(4, b"\0"))
            try:
                burst = await self._burst_read(opened.session, size)
                return burst if burst is not None else await self._read(opened.session, size)
            finally:
                await self._request(kCmdTerminateSession, session=opened.session, tolerant=True)

    async def _read(self, session: int, size: int) -> bytes:
        chunks: list[bytes] = []
        offset = 0
        while offset < size:
            reply = await self._request(
                kCmdReadFile, session=session, offset=offset, size=FTP_DATA_LEN, eof_ok=True
            )
            if reply.opcode == kRspNak or not reply.data:
                break  # EOF: the file is shorter than announced
            chunks.append(reply.data)
            offset += len(reply.data)
        return b"".join(chunks)

    async def _burst_read(self, session: int, size: int) -> bytes | None:
        """BurstReadFile: PX4 streams the file as ACKs (up to ~35 kB per burst) without a
        request each. A burst that ends early, or a packet lost, is followed by a new burst
        from the first byte missing. None when the vehicle does not know the command."""
        chunks: dict[int, bytes] = {}
        tries = 0
        while (start := _contiguous(chunks)) < size:
            self._seq = (self._seq + 1) & 0xFFFF
            payload = encode_payload(self._seq, session, kCmdBurstReadFile, start, b"", 0)
            self._burst = queue = asyncio.Queue[FtpReply]()
            try:
                self._send(self._mav.file_transfer_protocol_encode(0, *self._target, payload))
                while True:
                    try:
                        reply = await asyncio.wait_for(queue.get(), self.timeout_s)
                    except TimeoutError:
                        tries += 1
                        if tries > self.retries:
                            raise FtpError(kCmdBurstReadFile, "no answer") from None
                        break
                    if reply.opcode == kRspNak:
                        if reply.error == kErrUnknownCommand:
                            return None
                        if reply.error != kErrEOF:
                            raise FtpError(kCmdBurstReadFile, _error_name(reply.error))
                        # the end of the file is where the stream stopped (its offset)
                        size = min(size, max(reply.offset, _contiguous(chunks)))
                        break
                    if reply.data:
                        chunks[reply.offset] = reply.data
                    if reply.burst_complete or _contiguous(chunks) >= size:
                        break
            finally:
                self._burst = None
        data = bytearray()
        while chunks.get(len(data)):
            data += chunks[len(data)]
        return bytes(data[:size])

    async def _request(
        self,
        opcode: int,
        *,
        session: int = 0,
        offset: int = 0,
        data: bytes = b"",
        size: int | None = None,
        eof_ok: bool = False,
        tolerant: bool = False,
    ) -> FtpReply:
        """Send until answered; a retry keeps the sequence number so PX4 re-sends its
        answer instead of acting twice."""
        self._seq = (self._seq + 1) & 0xFFFF
        payload = encode_payload(self._seq, session, opcode, offset, data, size)
        loop = asyncio.get_running_loop()
        future: asyncio.Future[FtpReply] = loop.create_future()
        self._waiting = ((self._seq + 1) & 0xFFFF, future)
        try:
            for _ in range(1 + self.retries):
                self._send(self._mav.file_transfer_protocol_encode(0, *self._target, payload))
                try:
                    reply = await asyncio.wait_for(asyncio.shield(future), self.timeout_s)
                    break
                except TimeoutError:
                    continue
            else:
                if tolerant:
                    return FtpReply(0, session, kRspNak, opcode, offset, b"")
                raise FtpError(opcode, "no answer")
        finally:
            self._waiting = None
        if reply.opcode == kRspNak and not tolerant and not (eof_ok and reply.error == kErrEOF):
            raise FtpError(opcode, _error_name(reply.error))
        return reply


def _error_name(error: int) -> str:
    return FTP_ERROR_NAMES[error] if error < len(FTP_ERROR_NAMES) else str(error)


def _contiguous(chunks: dict[int, bytes]) -> int:
    """How many bytes from the start of the file have arrived without a hole."""
    end = 0
    while chunks.get(end):
        end += len(chunks[end])
    return end
