"""The link's tap only queues a frame; the loop routes it soon after, in order, and a queue
that the loop cannot empty keeps the newest frames."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from server.foxglove import bridge
from server.foxglove.bridge import FrameQueue


async def test_frames_are_routed_after_the_tap_returns_in_order() -> None:
    routed: list[Any] = []
    queue = FrameQueue(lambda msg, sent, t: routed.append((msg, sent, t)))
    for i in range(bridge.FRAME_BATCH * 2 + 3):
        queue.put(i, i % 2 == 0, float(i))
    assert routed == []  # the reader's callback encoded nothing
    await asyncio.sleep(0)
    assert len(routed) == bridge.FRAME_BATCH  # one batch per loop iteration
    for _ in range(3):
        await asyncio.sleep(0)
    assert [msg for msg, _, _ in routed] == list(range(bridge.FRAME_BATCH * 2 + 3))


async def test_a_full_queue_drops_its_oldest_frames_and_counts_them(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(bridge, "PENDING_FRAMES", 5)
    routed: list[Any] = []
    queue = FrameQueue(lambda msg, sent, t: routed.append(msg))
    for i in range(8):
        queue.put(i, False, 0.0)
    queue.flush()
    assert routed == [3, 4, 5, 6, 7]
    assert queue.dropped == 3
