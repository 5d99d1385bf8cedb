"""`skyhelm router`: a Zenoh router for sites where peers cannot find each other by multicast
(several hosts, networks that drop multicast, containers): edges and fleet servers connect to
it in client mode (``--zenoh-mode client --zenoh-connect tcp/<router>:7447``) and it routes
between them. It is plain Zenoh (eclipse-zenoh in mode "router"); it knows nothing of
SkyHelm's keys and carries no state of its own, so restarting it loses nothing but the
connections, which the sessions re-establish by themselves."""

from __future__ import annotations

import json
import signal
import socket
import threading
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType

import zenoh

DEFAULT_LISTEN = ["tcp/[::]:7447"]


@dataclass(frozen=True)
class RouterOptions:
    # e.g. tcp/0.0.0.0:7447, tls/0.0.0.0:7447; a port of 0 picks a free one
    listen: list[str] = field(default_factory=lambda: list(DEFAULT_LISTEN))
    # other routers to join (a mesh of sites)
    connect: list[str] = field(default_factory=list)
    # Zenoh JSON5 configuration (TLS, access control); listen/connect above override it
    config_file: Path | None = None
    multicast_scouting: bool = False


def _free_port(host: str, proto: str) -> int:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    kind = socket.SOCK_DGRAM if proto == "udp" else socket.SOCK_STREAM
    with socket.socket(family, kind) as probe:
        probe.bind((host, 0))
        port: int = probe.getsockname()[1]
        return port


def resolve_endpoint(endpoint: str) -> str:
    """``tcp/127.0.0.1:0`` -> ``tcp/127.0.0.1:<a free port>``: Zenoh does not report the
    port it picked, and the router's job is to tell its clients where it is."""
    proto, sep, address = endpoint.partition("/")
    locator, hash_, metadata = address.partition("#")
    host, colon, port = locator.rpartition(":")
    if not sep or not colon or port != "0" or proto not in ("tcp", "udp", "tls", "quic"):
        return endpoint
    bare = host[1:-1] if host.startswith("[") else host
    return f"{proto}/{host}:{_free_port(bare, 'udp' if proto in ('udp', 'quic') else 'tcp')}" + (
        hash_ + metadata
    )


def router_config(options: RouterOptions) -> tuple[zenoh.Config, list[str]]:
    """The router's configuration and the endpoints it listens on."""
    config = (
        zenoh.Config.from_file(str(options.config_file))
        if options.config_file is not None else zenoh.Config()
    )
    listen = [resolve_endpoint(e) for e in options.listen]
    config.insert_json5("mode", json.dumps("router"))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(listen))
    if options.connect:
        config.insert_json5("connect/endpoints", json.dumps(options.connect))
    config.insert_json5("scouting/multicast/enabled", json.dumps(options.multicast_scouting))
    return config, listen


def run_router(options: RouterOptions) -> int:
    """Run until SIGTERM or SIGINT; prints the endpoints it listens on, then "ready"."""
    config, listen = router_config(options)
    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        stop.set()

    previous = {
        sig: signal.signal(sig, on_signal) for sig in (signal.SIGTERM, signal.SIGINT)
    }
    try:
        with zenoh.open(config) as session:
            for endpoint in listen:
                print(f"SkyHelm router listening: {endpoint}", flush=True)
            print(f"SkyHelm router ready: zid {session.zid()}", flush=True)
            while not stop.wait(0.5):
                pass
            print("SkyHelm router stopping", flush=True)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0
