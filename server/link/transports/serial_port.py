"""A serial port (``DEVICE:BAUD``), read by one thread that hands its bytes to the event loop,
where they are decoded; reopened with backoff when the device goes away (a cable pulled)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from typing import Any

from server.link.codec.urls import LinkUrl
from server.link.transports.base import FrameDecoder, FrameSink, Transport, deliver

log = logging.getLogger(__name__)

_SERIAL_READ_TIMEOUT_S = 0.05
_JOIN_TIMEOUT_S = 2.0


class SerialTransport(Transport):
    """A serial port read by one thread; reopened with backoff when the device goes away."""

    def __init__(self, address: LinkUrl) -> None:
        super().__init__(address)
        self._serial: Any = None  # serial.Serial while open
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._decoder = FrameDecoder()

    async def start(self, sink: FrameSink) -> None:
        self._sink = sink
        self._decoder = self._new_decoder()
        loop = asyncio.get_running_loop()
        self._thread = threading.Thread(
            target=self._read_forever, args=(loop, sink), name=f"serial:{self.address.device}",
            daemon=True,
        )
        self._thread.start()

    def write(self, frame: bytes, target_system: int | None) -> bool:
        import serial

        port = self._serial
        if port is None:
            return False
        try:
            # write_timeout=0 makes this non-blocking: a full driver buffer raises instead.
            return bool(port.write(frame) == len(frame))
        except (serial.SerialException, OSError):
            return False

    async def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, _JOIN_TIMEOUT_S)
            self._thread = None

    def _read_forever(self, loop: asyncio.AbstractEventLoop, sink: FrameSink) -> None:
        import serial

        while not self._stop.is_set():
            try:
                port = serial.Serial(
                    self.address.device, self.address.baud,
                    timeout=_SERIAL_READ_TIMEOUT_S, write_timeout=0,
                )
            except (serial.SerialException, OSError) as exc:
                log.debug("%s: open failed (%s)", self.address.url, exc)
                self._stop.wait(self.backoff_s)
                self._waited_in_vain()
                continue
            self._opened()
            self._serial = port
            loop.call_soon_threadsafe(sink.connection_changed, True)
            try:
                self._read_until_lost(port, loop, sink)
            except RuntimeError:  # the loop closed under us: nothing left to deliver to
                self._stop.set()
            finally:
                self._serial = None
                with contextlib.suppress(Exception):
                    port.close()
                with contextlib.suppress(RuntimeError):  # the loop may be gone at shutdown
                    loop.call_soon_threadsafe(sink.connection_changed, False)
            self._stop.wait(self.backoff_s)

    def _read_until_lost(self, port: Any, loop: asyncio.AbstractEventLoop, sink: FrameSink) -> None:
        import serial

        try:
            while not self._stop.is_set():
                data = port.read(max(1, port.in_waiting))
                if data:
                    loop.call_soon_threadsafe(self._deliver, sink, bytes(data))
        except (serial.SerialException, OSError, TypeError) as exc:
            log.info("%s: device lost (%s)", self.address.url, exc)

    def _deliver(self, sink: FrameSink, data: bytes) -> None:
        # Runs on the loop, so the decoder is only ever touched there.
        deliver(sink, self._decoder, data, None, datagram=False)
