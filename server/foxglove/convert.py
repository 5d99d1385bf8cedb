"""`skyhelm convert FLIGHT.tlog FLIGHT.mcap`: a recorded .tlog as MCAP, with the channels a
live MCAP recording has, less those only the running server knows (state, health, events):
every MAVLink message on its channel, the pose, position and status texts derived from
them. Frames from the ground station's ids (255/190, SkyHelm's own) count as sent."""

from __future__ import annotations

import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import foxglove
from mcap.reader import make_reader
from pymavlink.dialects.v20 import development as mavlink

from server.foxglove.channels import LinkChannels
from server.foxglove.router import FrameRouter
from server.link.codec import px4_messages
from server.link.codec.tlog import iter_tlog

GCS_SYSID = 255
GCS_COMPID = 190


@dataclass
class Conversion:
    """What a conversion wrote: messages per MAVLink type, and frames it could not decode."""

    messages: Counter[str] = field(default_factory=Counter)
    undecodable: int = 0

    @property
    def total(self) -> int:
        return sum(self.messages.values())


def convert_tlog(source: Path, target: Path, *, overwrite: bool = False) -> Conversion:
    context = foxglove.Context()
    router = FrameRouter(LinkChannels(context, source.stem))
    codec = mavlink.MAVLink(None)
    result = Conversion()
    with foxglove.open_mcap(target, allow_overwrite=overwrite, context=context):
        for unix_time_s, frame in iter_tlog(source):
            msg = decode_frame(codec, frame)
            if msg is None:
                result.undecodable += 1
                continue
            sent = (msg.get_srcSystem(), msg.get_srcComponent()) == (GCS_SYSID, GCS_COMPID)
            router.frame(msg, sent, unix_time_s)
            result.messages[msg.get_type()] += 1
    router.channels.close()
    return result


def decode_frame(codec: mavlink.MAVLink, frame: bytes) -> mavlink.MAVLink_message | None:
    """A frame as the link decoded it (PX4's own messages too), or None."""
    try:
        msg = codec.decode(bytearray(frame))
    except mavlink.MAVError:
        return None
    if isinstance(msg, mavlink.MAVLink_unknown):
        return px4_messages.decode_unknown(msg)
    return msg


def run_convert_command(source: Path, target: Path, *, overwrite: bool) -> int:
    """`skyhelm convert`: 0, or 2 with the reason when a file cannot be read or written.
    The summary printed is read back from the MCAP file as written."""
    if not source.is_file():
        print(f"skyhelm convert: no .tlog at {source}", file=sys.stderr)
        return 2
    if target.exists() and not overwrite:
        print(f"skyhelm convert: {target} exists (--force overwrites it)", file=sys.stderr)
        return 2
    try:
        result = convert_tlog(source, target, overwrite=overwrite)
    except (OSError, RuntimeError) as exc:
        print(f"skyhelm convert: {exc}", file=sys.stderr)
        return 2
    with target.open("rb") as file:
        summary = make_reader(file).get_summary()
    written = summary.statistics.message_count if summary and summary.statistics else 0
    channels = len(summary.channels) if summary else 0
    print(f"{target}: {written} messages on {channels} channels "
          f"({result.total} MAVLink messages of {len(result.messages)} types"
          + (f", {result.undecodable} frames not decodable" if result.undecodable else "")
          + ")")
    return 0
