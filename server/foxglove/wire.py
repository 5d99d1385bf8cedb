"""What the server and its Foxglove process (worker.py) say to each other.

To the worker, on its stdin, records: a header (record kind, link index, a byte of
argument, Unix time, payload length) and the payload:

- LINK: a link to show (payload JSON: its name and the MCAP file to write, or null)
- FRAME: a MAVLink frame of that link, as the .tlog has it (argument: 1 if sent by us)
- STATE, HEALTH: a vehicle's state or health JSON (argument: its system id)
- EVENT: a server event as a log line (payload JSON: system id, level, name, text)
- VEHICLE: a vehicle the link discovered (argument: its system id): its state and health
  channels are offered from then on

From the worker, on its stdout, one JSON object a line: ``{"ready": PORT}`` (null without a
server) once it listens, then ``{"readers": [SYSID, ...]}`` whenever the set of vehicles
whose state or health someone reads changes.
"""

from __future__ import annotations

import struct

HEADER = struct.Struct("<BBBdI")
LINK, FRAME, STATE, HEALTH, EVENT, VEHICLE = 1, 2, 3, 4, 5, 6


def record(kind: int, link: int, argument: int, unix_time_s: float, payload: bytes) -> bytes:
    return HEADER.pack(kind, link, argument, unix_time_s, len(payload)) + payload
