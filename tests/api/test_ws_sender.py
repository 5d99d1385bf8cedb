"""A telemetry socket's sends on virtual loop time: a send stuck for SEND_TIMEOUT_S closes
the client (1008) however many sends went before, and sends that complete never do, with
no timer per message."""

from __future__ import annotations

import asyncio
from typing import Any, cast

import pytest
from fastapi import WebSocket, WebSocketDisconnect
from starlette.websockets import WebSocketState

from server.http.ws_common import SEND_TIMEOUT_S, Sender
from server.link.codec.aio import loop_time_s

pytestmark = pytest.mark.looptime


class FakeSocket:
    """Sends complete at once until `stall` is set; then they wait until closed."""

    def __init__(self) -> None:
        self.application_state = WebSocketState.CONNECTED
        self.sent: list[str] = []
        self.closed_with: tuple[int, str] | None = None
        self.stall = False
        self._closed = asyncio.Event()

    async def send_text(self, text: str) -> None:
        if self.stall:
            await self._closed.wait()
            raise RuntimeError('Cannot call "send" once a close message has been sent.')
        self.sent.append(text)

    async def close(self, code: int, reason: str = "") -> None:
        self.closed_with = (code, reason)
        self.application_state = WebSocketState.DISCONNECTED
        self._closed.set()


def _sender(socket: FakeSocket) -> Sender:
    return Sender(cast(WebSocket, socket))


def _count_timers(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The times of every timer the running loop is asked for from now on."""
    loop: Any = asyncio.get_running_loop()
    asked: list[float] = []
    call_at = loop.call_at

    def counting(when: float, *args: Any, **kwargs: Any) -> Any:
        asked.append(when)
        return call_at(when, *args, **kwargs)

    monkeypatch.setattr(loop, "call_at", counting)
    return asked


async def test_a_stuck_send_closes_the_client_after_the_timeout() -> None:
    socket = FakeSocket()
    sender = _sender(socket)
    for i in range(50):  # a slow start: the watchdog is armed by the first of these
        await sender.send_text(f"state {i}")
        await asyncio.sleep(0.1)
    socket.stall = True
    stalled_s = loop_time_s()
    with pytest.raises(WebSocketDisconnect) as raised:
        await sender.send_text("never delivered")
    assert raised.value.code == 1008
    assert socket.closed_with == (1008, "client too slow")
    assert SEND_TIMEOUT_S <= loop_time_s() - stalled_s <= SEND_TIMEOUT_S + 0.01
    assert len(socket.sent) == 50


async def test_sends_that_complete_never_close_and_arm_no_timer_each(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    socket = FakeSocket()
    sender = _sender(socket)
    timers = _count_timers(monkeypatch)
    for i in range(200):
        await sender.send_text(f"state {i}")
    assert len(timers) == 1  # one watchdog for the socket, not one per message
    await asyncio.sleep(3 * SEND_TIMEOUT_S)
    await sender.send_json({"type": "event"})
    assert socket.closed_with is None
    assert len(socket.sent) == 201


async def test_cancelling_a_stuck_send_from_outside_is_not_taken_for_a_timeout() -> None:
    socket = FakeSocket()
    sender = _sender(socket)
    socket.stall = True
    task = asyncio.create_task(sender.send_text("stuck"))
    await asyncio.sleep(1.0)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    await asyncio.sleep(2 * SEND_TIMEOUT_S)  # the watchdog finds nothing pending
    assert socket.closed_with is None
