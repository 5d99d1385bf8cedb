"""Messages per MAVLink type: in a .tlog, and on an MCAP file's MAVLink channels."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from server.link.codec import px4_messages


def tlog_counts(records: Iterable[tuple[float, bytes]]) -> Counter[str]:
    codec = mavlink.MAVLink(None)
    counts: Counter[str] = Counter()
    for _, frame in records:
        msg = codec.decode(bytearray(frame))
        if isinstance(msg, mavlink.MAVLink_unknown):
            msg = px4_messages.decode_unknown(msg) or msg
        counts[msg.get_type()] += 1
    return counts


def mcap_mavlink_counts(reader: Any) -> Counter[str]:
    """Per type, over every ``…/mavlink/<TYPE>`` and ``…/sent/<TYPE>`` channel."""
    counts: Counter[str] = Counter()
    for _, channel, _ in reader.iter_messages():
        *_, direction, kind = channel.topic.split("/")
        if direction in ("mavlink", "sent"):
            counts[kind] += 1
    return counts


def mcap_topics(reader: Any) -> set[str]:
    """The topics that hold at least one message."""
    return {channel.topic for _, channel, _ in reader.iter_messages()}
