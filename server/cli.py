"""The `skyhelm` command: `serve` (the dashboard), `replay` (the dashboard, read-only, from a
recorded .tlog), `sim` (the simulated vehicle alone), `router` (a Zenoh router for a fleet),
`convert` (a .tlog to MCAP)."""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import sys
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import uvicorn

from server import map_tiles
from server.http.security import RedactTokens
from server.settings import Settings, SettingsError, load_settings

log = logging.getLogger("server")

__all__ = [
    "RedactTokens",
    "build_parser",
    "main",
    "ready_url",
    "settings_from_args",
    "uvicorn_server",
]


def configure_logging(level: str) -> None:
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    handler.addFilter(RedactTokens())
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level.upper())


def _server_options(parser: argparse.ArgumentParser) -> None:
    """Options of every command that serves the dashboard."""
    parser.add_argument("--config", type=Path, help="TOML file with the same settings")
    parser.add_argument("--host", help="bind address (default 127.0.0.1)")
    parser.add_argument("--port", type=int, help="HTTP port; 0 picks a free one (default 8000)")
    parser.add_argument(
        "--token", help="pilot token (default: generated once, kept in --token-file)"
    )
    parser.add_argument(
        "--token-file", type=Path, metavar="FILE",
        help="where the generated token is kept, 0600 (default $XDG_STATE_HOME/skyhelm/token)",
    )
    parser.add_argument("--observer-token", help="read-only token")
    parser.add_argument("--cors-origin", action="append", dest="cors_origins", metavar="ORIGIN")
    parser.add_argument("--no-scene", action="store_true", help="do not start the 3D scene")
    parser.add_argument("--map-tile-url", help="2D map tiles ({z}/{x}/{y}); default: a grid")
    parser.add_argument(
        "--map-tiles", type=Path, metavar="FILE",
        help="offline 2D map tiles: a PMTiles or MBTiles archive (skyhelm tiles makes one)",
    )
    parser.add_argument("--tls-cert", type=Path, help="PEM certificate: serve https and wss")
    parser.add_argument("--tls-key", type=Path, help="PEM private key of --tls-cert")
    parser.add_argument(
        "--no-access-log", action="store_true", help="no request log (tokens are redacted in it)"
    )
    parser.add_argument("--foxglove-port", type=int,
                        help="Foxglove WebSocket server on 127.0.0.1 (0: a free port; default "
                             "off); with a token through /api/v1/foxglove (docs/foxglove.md)")
    parser.add_argument("--log-level", default="info", help="debug|info|warning|error")


def _dashboard_command(sub: Any, name: str, help_text: str) -> argparse.ArgumentParser:
    """A command that serves the dashboard; options left out keep the settings' values."""
    parser: argparse.ArgumentParser = sub.add_parser(
        name, help=help_text, argument_default=argparse.SUPPRESS
    )
    _server_options(parser)
    return parser


def _serve_parser(sub: Any) -> None:
    serve = _dashboard_command(
        sub, "serve", "run the dashboard (with a simulated vehicle unless --connect is given)"
    )
    serve.add_argument(
        "--connect",
        action="append",
        metavar="URL",
        help="vehicle link, e.g. udpin:127.0.0.1:14540 (repeatable; none = simulated vehicle)",
    )
    serve.add_argument("--sim-airframe", help="quad|hexa|octo|plane|vtol|rover")
    serve.add_argument("--sim-count", type=int, help="number of simulated vehicles")
    serve.add_argument("--sim-speed", type=float, help="simulated time per wall second")
    serve.add_argument("--rate-hz", type=float, help="offboard setpoint stream rate")
    serve.add_argument("--lease-ttl-s", type=float, help="control lease TTL (default 120)")
    serve.add_argument("--on-operator-loss", help="hold|land|rtl|hold-mode|continue")
    serve.add_argument("--max-alt-rel-m", type=float, help="envelope: altitude above home")
    serve.add_argument("--max-distance-m", type=float, help="envelope: distance from home")
    serve.add_argument("--max-speed-xy-m-s", type=float, help="envelope: horizontal speed")
    serve.add_argument("--max-speed-z-m-s", type=float, help="envelope: vertical speed")
    serve.add_argument("--log-dir", type=Path, help="where .tlog recordings go (default logs)")
    serve.add_argument("--no-tlog", action="store_true", help="record no .tlog")
    serve.add_argument("--mcap", action="store_true",
                       help="record an MCAP file beside each .tlog (docs/foxglove.md)")
    serve.add_argument("--signing-key-file", type=Path,
                       help="MAVLink 2 signing key file (a path: the key itself never goes on "
                            "the command line); POST /api/v1/signing creates it")
    _fleet_flags(serve)
    _numeric_setting_flags(serve)


def _fleet_flags(parser: argparse.ArgumentParser) -> None:
    fleet = parser.add_argument_group("fleet over Zenoh (docs/fleet.md)")
    fleet.add_argument("--zenoh", action="store_true",
                       help="publish this server's vehicles to the fleet (an edge)")
    fleet.add_argument("--fleet", action="store_true",
                       help="see and fly every vehicle of the fleet (no simulated vehicle of its "
                       "own unless --sim-count is given)")
    fleet.add_argument("--fleet-name", help="the fleet's name (default 'default')")
    fleet.add_argument("--edge-name", help="this edge's name (default: the host name)")
    fleet.add_argument("--zenoh-mode", help="peer (default) or client (through a router)")
    fleet.add_argument("--zenoh-connect", action="append", metavar="ENDPOINT",
                       help="a Zenoh endpoint to connect to, e.g. tcp/10.0.0.2:7447")
    fleet.add_argument("--zenoh-listen", action="append", metavar="ENDPOINT",
                       help="a Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447")
    fleet.add_argument("--no-zenoh-multicast-scouting", action="store_false",
                       dest="zenoh_multicast_scouting",
                       help="find peers only through --zenoh-connect")
    fleet.add_argument("--zenoh-config", type=Path, help="Zenoh JSON5 configuration file")


def _numeric_setting_flags(parser: argparse.ArgumentParser) -> None:
    """A flag for every numeric setting that has none above, so each can be given, and is
    checked, from the command line as from the environment."""
    for name, field in Settings.model_fields.items():
        flag = "--" + name.replace("_", "-")
        kinds = typing.get_args(field.annotation) or (field.annotation,)
        kind = next((k for k in kinds if k in (int, float)), None)
        if kind is None or flag in parser._option_string_actions:
            continue
        help_text = f"{field.description} " if field.description else ""
        parser.add_argument(flag, type=kind, help=f"{help_text}(default {field.default})")


def _replay_parser(sub: Any) -> None:
    replay = _dashboard_command(
        sub,
        "replay",
        "serve the dashboard, read-only, from a recorded .tlog (no simulated vehicle)",
    )
    replay.add_argument("file", type=Path, help="a .tlog, e.g. logs/20260101T120000Z-....tlog")
    replay.add_argument(
        "--speed", type=float, default=1.0, help="recorded seconds per wall second (default 1)"
    )
    replay.add_argument("--loop", action="store_true", help="start over at the end of the file")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="skyhelm", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    _serve_parser(sub)
    _replay_parser(sub)
    # `skyhelm sim` hands every argument to `python -m sim`, see main().
    sub.add_parser("sim", help="run the simulated PX4 vehicle alone, like PX4 SITL (sim --help)")
    _router_parser(sub)
    convert = sub.add_parser("convert", help="write a recorded .tlog as MCAP (docs/foxglove.md)")
    convert.add_argument("tlog", type=Path, help="the .tlog to read")
    convert.add_argument("mcap", type=Path, help="the MCAP file to write")
    convert.add_argument("--force", action="store_true", help="overwrite an existing MCAP file")
    tiles = sub.add_parser(
        "tiles", help="fetch an offline 2D map archive for --map-tiles (while online)",
        description=map_tiles.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    map_tiles.add_arguments(tiles)
    return parser


def _router_parser(sub: Any) -> None:
    router = sub.add_parser(
        "router", help="run a Zenoh router that edges and fleet servers connect to (docs/fleet.md)"
    )
    router.add_argument("--listen", action="append", metavar="ENDPOINT",
                        help="an endpoint to listen on (repeatable; default tcp/[::]:7447; "
                             "port 0 picks a free one)")
    router.add_argument("--connect", action="append", metavar="ENDPOINT",
                        help="another router to join (repeatable)")
    router.add_argument("--zenoh-config", type=Path,
                        help="Zenoh JSON5 configuration file (TLS, access control)")
    router.add_argument("--multicast-scouting", action="store_true",
                        help="also answer multicast scouting on the LAN (default off)")
    router.add_argument("--log-level", default="info", help="debug|info|warning|error")


def run_router_command(args: argparse.Namespace) -> int:
    from server.fleet.router import DEFAULT_LISTEN, RouterOptions, run_router

    options = RouterOptions(
        listen=args.listen or list(DEFAULT_LISTEN),
        connect=args.connect or [],
        config_file=args.zenoh_config,
        multicast_scouting=args.multicast_scouting,
    )
    try:
        return run_router(options)
    except Exception as exc:  # zenoh raises ZError on a bad endpoint or config
        print(f"skyhelm router: {exc}", file=sys.stderr)
        return 2


def replay_url(file: Path, speed: float, loop: bool) -> str:
    """The ``tlog:`` link that replays ``file``."""
    if not file.is_file():
        raise SettingsError(f"no recording at {file}")
    return f"tlog:{file}?speed={speed:g}&loop={int(loop)}"


def settings_from_args(args: argparse.Namespace) -> Settings:
    flags = dict(vars(args))
    ours = ("command", "config", "log_level", "no_tlog", "no_scene", "no_access_log")
    for name in (*ours, "file", "speed", "loop"):
        flags.pop(name, None)
    if args.command == "replay":
        flags["connect"] = [replay_url(args.file, args.speed, getattr(args, "loop", False))]
        flags["log_dir"] = None
    if getattr(args, "no_tlog", False):
        flags["log_dir"] = None
    if getattr(args, "no_scene", False):
        flags["scene"] = False
    if getattr(args, "no_access_log", False):
        flags["access_log"] = False
    return load_settings(getattr(args, "config", None), keep_token=True, **flags)


def ready_url(settings: Settings, port: int) -> str:
    host = settings.host
    if host in ("0.0.0.0", "::", ""):
        host = "127.0.0.1"
    if ":" in host:
        host = f"[{host}]"
    scheme = "https" if settings.tls else "http"
    return f"{scheme}://{host}:{port}/?token={settings.pilot_token()}"


# How long an idle HTTP connection stays open (uvicorn's default: 5 s). A client that pools
# connections (httpx keeps them 5 s, requests with no limit) and sends on one just as the
# server closes it gets "connection reset" for a request the server never saw. Longer than
# httpx's 5 s, the client closes first; nginx's default is the same 75 s.
KEEP_ALIVE_S = 75


def uvicorn_server(settings: Settings) -> uvicorn.Server:
    """The server `skyhelm serve` runs: https and wss when a TLS certificate is set."""
    from server.app import create_app

    config = uvicorn.Config(
        create_app(settings, freeze_gc_at_start=True),
        host=settings.host,
        port=settings.port,
        log_config=None,
        # records are redacted as they are made (security.install_log_redaction): no token
        access_log=settings.access_log,
        ssl_certfile=settings.tls_cert,
        ssl_keyfile=settings.tls_key,
        lifespan="on",
        timeout_keep_alive=KEEP_ALIVE_S,
        ws="websockets-sansio",
        # Telemetry is small and mostly local: compressing 1000 messages/s costs more CPU
        # than the bandwidth it saves.
        ws_per_message_deflate=False,
    )
    return uvicorn.Server(config)


async def serve(settings: Settings) -> int:
    server = uvicorn_server(settings)
    running = asyncio.create_task(server.serve())
    while not server.started:
        if running.done():
            await running
            print("skyhelm: the server did not start (see the log above)", file=sys.stderr)
            return 1
        await asyncio.sleep(0.05)
    port = server.servers[0].sockets[0].getsockname()[1]
    print(f"SkyHelm ready: {ready_url(settings, port)}", flush=True)
    foxglove = getattr(getattr(server.config.app, "state", None), "foxglove", None)
    if foxglove is not None and foxglove.server_port is not None:
        url = ready_url(settings, port).replace("http", "ws", 1).replace("/?", "/api/v1/foxglove?")
        print(f"Foxglove: ws://127.0.0.1:{foxglove.server_port} on this machine, or {url}",
              flush=True)
    await running
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["sim"]:
        os.execv(sys.executable, [sys.executable, "-m", "sim", *argv[1:]])
    args = build_parser().parse_args(argv)
    configure_logging(getattr(args, "log_level", "info"))
    if args.command == "router":
        return run_router_command(args)
    if args.command == "tiles":
        return map_tiles.run(args)
    if args.command == "convert":
        from server.foxglove.convert import run_convert_command

        return run_convert_command(args.tlog, args.mcap, overwrite=args.force)
    try:
        settings = settings_from_args(args)
    except SettingsError as exc:
        print(f"skyhelm: {exc}", file=sys.stderr)
        return 2
    try:
        return asyncio.run(serve(settings))
    except SettingsError as exc:  # found while building the app (a tile archive it opens)
        print(f"skyhelm: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0


if __name__ == "__main__":
    sys.exit(main())
