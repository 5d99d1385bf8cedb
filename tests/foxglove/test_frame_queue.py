"""The link's tap only queues a frame; the loop hands the frames on soon after, in order and
in batches, and a queue that the loop cannot empty keeps the newest frames."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from server.foxglove import bridge
from server.foxglove.bridge import FrameQueue


async def test_frames_go_on_after_the_tap_returns_in_order_and_in_batches() -> None:
    batches: list[list[Any]] = []
    queue = FrameQueue(batches.append)
    count = bridge.FRAME_BATCH * 2 + 3
    for i in range(count):
        queue.put(i, i % 2 == 0, float(i))
    assert batches == []  # the reader's callback handed nothing on
    await asyncio.sleep(0)
    assert [len(batch) for batch in batches] == [bridge.FRAME_BATCH]  # one per iteration
    for _ in range(3):
        await asyncio.sleep(0)
    assert [msg for batch in batches for msg, _, _ in batch] == list(range(count))


async def test_a_full_queue_drops_its_oldest_frames_and_counts_them(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(bridge, "PENDING_FRAMES", 5)
    batches: list[list[Any]] = []
    queue = FrameQueue(batches.append)
    for i in range(8):
        queue.put(i, False, 0.0)
    queue.flush()
    assert [msg for batch in batches for msg, _, _ in batch] == [3, 4, 5, 6, 7]
    assert queue.dropped == 3
