"""Foxglove adapter: the vehicles live on a Foxglove WebSocket server (foxglove-sdk) and in
MCAP files, both in a process of their own, and a .tlog converts to MCAP
(docs/foxglove.md). Nothing here is imported by server.link; it reads the link through
frame taps, vehicle events and the API's publishers."""

from server.foxglove.bridge import FoxgloveBridge
from server.foxglove.proxy import FoxgloveProxy

__all__ = ["FoxgloveBridge", "FoxgloveProxy"]
