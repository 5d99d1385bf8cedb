"""The Zenoh session of a server: peer mode by default, a router's address when given."""

from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import zenoh

from server.settings import Settings

ZenohMode = Literal["peer", "client", "router"]

# The link lease this node announces, and keep-alives per lease: a peer that dies or is cut
# off is dropped (and its liveliness tokens with it) within LEASE_MS of its last message,
# so the fleet sees an edge lost within 2 s. Zenoh's default is 10 s. A config file's own
# transport/link/tx/lease wins.
LEASE_MS = 1000
KEEP_ALIVES_PER_LEASE = 4
_DEFAULT_LEASE_MS = 10000


@dataclass(frozen=True)
class ZenohOptions:
    mode: ZenohMode = "peer"
    # e.g. tcp/10.0.0.2:7447 (a router, or peers to reach without scouting)
    connect: list[str] = field(default_factory=list)
    # e.g. tcp/0.0.0.0:7447; empty = Zenoh's default
    listen: list[str] = field(default_factory=list)
    # multicast scouting finds peers on the LAN; off when every peer is named in connect
    multicast_scouting: bool = True
    # a Zenoh JSON5 configuration file (TLS, access control); the options above override it
    config_file: Path | None = None


def options_from_settings(settings: Settings) -> ZenohOptions:
    """The Zenoh options a server's settings give (edges and fleet servers alike)."""
    return ZenohOptions(
        mode=settings.zenoh_mode,
        connect=list(settings.zenoh_connect),
        listen=list(settings.zenoh_listen),
        multicast_scouting=settings.zenoh_multicast_scouting,
        config_file=settings.zenoh_config,
    )


def zenoh_config(options: ZenohOptions) -> zenoh.Config:
    config = (
        zenoh.Config.from_file(str(options.config_file))
        if options.config_file is not None else zenoh.Config()
    )
    config.insert_json5("mode", json.dumps(options.mode))
    if options.connect:
        config.insert_json5("connect/endpoints", json.dumps(options.connect))
    if options.listen:
        config.insert_json5("listen/endpoints", json.dumps(options.listen))
    config.insert_json5("scouting/multicast/enabled", json.dumps(options.multicast_scouting))
    if json.loads(config.get_json("transport/link/tx/lease")) == _DEFAULT_LEASE_MS:
        config.insert_json5("transport/link/tx/lease", json.dumps(LEASE_MS))
        config.insert_json5("transport/link/tx/keep_alive", json.dumps(KEEP_ALIVES_PER_LEASE))
    return config


def open_session(options: ZenohOptions) -> zenoh.Session:
    """Open a session (blocking; call it off the event loop)."""
    return zenoh.open(zenoh_config(options))


def undeclare(*entities: Any) -> None:
    """Undeclare Zenoh subscribers, queryables, publishers or tokens (None is skipped);
    one whose session closed first is gone already."""
    for entity in entities:
        if entity is not None:
            with contextlib.suppress(zenoh.ZError):
                entity.undeclare()
