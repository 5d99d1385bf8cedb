"""WebSockets: telemetry for anyone with a token (ws_telemetry.py), the control session for
one pilot (ws_control.py); admission, sends and close codes are shared (ws_common.py).

Slow-client policy: state is latest-wins (slots.py); statustext, events and send
timeouts as ws_common.py says."""

from __future__ import annotations

from server.api import ws_control, ws_telemetry
from server.api.ws_telemetry import MIN_RATE_HZ
from server.control.views import event_message
from server.http.ws_common import (
    CLOSE_FORBIDDEN,
    CLOSE_LEASE_HELD,
    CLOSE_LEASE_LOST,
    CLOSE_NOT_FOUND,
    CLOSE_UNAUTHORIZED,
    EVENT_BACKLOG,
    SEND_TIMEOUT_S,
)

# the telemetry socket, then the control session (create_app mounts them in this order)
ROUTERS = (ws_telemetry.router, ws_control.router)

__all__ = [
    "CLOSE_FORBIDDEN",
    "CLOSE_LEASE_HELD",
    "CLOSE_LEASE_LOST",
    "CLOSE_NOT_FOUND",
    "CLOSE_UNAUTHORIZED",
    "EVENT_BACKLOG",
    "MIN_RATE_HZ",
    "ROUTERS",
    "SEND_TIMEOUT_S",
    "event_message",
]
