"""Every WebSocket under ``/api/v1``, written once beside the call table: its name, its path
under the API, who may open it and what it is for.

What follows from it: the server's socket routes (each handler is registered at its
socket's ``route`` and admits the token its ``access`` asks for), the Python client's
socket URL and the page's (``SOCKETS`` in ``web/calls.js``, written by
``python -m tools.gen_calls_js``); ``tests/test_calls.py`` fails on a socket route under
the API that is not here, and on a socket's path written by hand in the page.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from skyhelm_wire.calls import API_PREFIX

# who may open a socket: any token ("read") or the pilot token ("pilot")
SocketAccess = Literal["read", "pilot"]


@dataclass(frozen=True)
class SocketSpec:
    """One socket: ``path`` is under the API (``ws/telemetry``), ``access`` who may open
    it, ``purpose`` what it carries (the messages are ``skyhelm_wire.messages``)."""

    name: str
    path: str
    access: SocketAccess
    purpose: str

    @property
    def route(self) -> str:
        """The path under the API (``/ws/telemetry``)."""
        return f"/{self.path}"

    @property
    def url_path(self) -> str:
        """The path a client opens (``/api/v1/ws/telemetry``)."""
        return f"{API_PREFIX}{self.route}"


SOCKETS: tuple[SocketSpec, ...] = (
    SocketSpec("telemetry", "ws/telemetry", "read",
               "one vehicle's (or every vehicle's) states at the asked rate, its events and "
               "STATUSTEXTs, the vehicle list and clicks in the 3D scene"),
    SocketSpec("control", "ws/control", "pilot",
               "the pilot session: holds the vehicle's control lease while open and carries "
               "setpoints, sticks, commands and answers to takeover requests"),
    # a fleet server's (--fleet)
    SocketSpec("fleet", "fleet/ws", "read",
               "every fleet vehicle's state at the asked rate, presence and events"),
    # with --foxglove-port: the Foxglove server's socket behind the app's port and token
    SocketSpec("foxglove", "foxglove", "read",
               "the Foxglove WebSocket protocol (foxglove.websocket.v1), relayed"),
)  # fmt: skip
SOCKET: dict[str, SocketSpec] = {socket.name: socket for socket in SOCKETS}
