"""The Foxglove worker finishes its MCAP files' chunks every MCAP_FLUSH_S while records keep
coming, between records: its flushing thread alone had to win the lock from a reader working
through a backlog, and a crash beside busy loops lost 1.28 s of recording."""

from __future__ import annotations

import io
import itertools
import json

from server.foxglove import wire
from server.foxglove.worker import MCAP_FLUSH_S, Worker, serve

RECORD_EVERY_S = 0.1
RECORDS = 30  # 3 s of them


class Clock:
    def __init__(self) -> None:
        self.now_s = 1000.0

    def __call__(self) -> float:
        return self.now_s


class Records(io.BytesIO):
    """A link, then frames the worker cannot decode (it skips them), RECORD_EVERY_S apart
    on the clock: each header read moves it on."""

    def __init__(self, clock: Clock) -> None:
        link = json.dumps({"name": "udp", "mcap": None}).encode()
        frames = [wire.record(wire.FRAME, 0, 0, 0.0, b"\x00") for _ in range(RECORDS)]
        super().__init__(wire.record(wire.LINK, 0, 0, 0.0, link) + b"".join(frames))
        self.clock = clock

    def read(self, size: int | None = -1) -> bytes:
        if size == wire.HEADER.size:
            self.clock.now_s += RECORD_EVERY_S
        return super().read(size)


class Writer:
    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self.flushed_s: list[float] = []

    def flush(self) -> None:
        self.flushed_s.append(self.clock.now_s)


def test_records_that_keep_coming_are_flushed_on_time() -> None:
    clock = Clock()
    worker = Worker(None, io.BytesIO())
    worker.clock = clock
    worker.flushed_s = clock.now_s
    writer = Writer(clock)
    worker.writers.append(writer)  # type: ignore[arg-type]
    start_s = clock.now_s
    serve(Records(clock), worker)  # no flushing thread: serve() alone
    assert not worker.failed
    ends = [start_s, *writer.flushed_s, clock.now_s]
    assert len(writer.flushed_s) >= 5
    assert max(b - a for a, b in itertools.pairwise(ends)) <= MCAP_FLUSH_S + RECORD_EVERY_S
