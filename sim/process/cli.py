"""`python -m sim` / `skyhelm sim`: run simulated PX4 vehicles like PX4 SITL does."""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import signal
import sys
from collections.abc import Sequence
from pathlib import Path

from sim.models.airframes import AIRFRAME_NAMES
from sim.process.run_loop import FAST_FORWARD_SPEED
from sim.process.runner import SimCluster
from sim.process.sim_processes import run_processes, stop_event

# PX4 SITL's ports for instance 0 (instance i adds i, except the shared GCS port).
SITL_API_REMOTE_PORT = 14540
SITL_GCS_REMOTE_PORT = 14550
SITL_API_LOCAL_PORT = 14580
SITL_GCS_LOCAL_PORT = 18570
# Vehicles one process steps by default: a quad costs ~2.7 % of a core, so 16 of them keep
# a process's loop well inside its 20 ms wake period, and more processes use more cores.
VEHICLES_PER_PROCESS = 16
FAST_FORWARD = signal.SIGUSR1
REAL_PACE = signal.SIGUSR2


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="skyhelm sim",
        description="Simulated PX4 v1.16 vehicles on UDP, like PX4 SITL.",
    )
    parser.add_argument("--instance", type=int, default=0,
                        help="first instance index (sysid = index + 1)")
    parser.add_argument("--count", type=int, default=1, help="number of vehicles")
    parser.add_argument("--processes", type=int, default=0,
                        help="spread the vehicles over this many processes (instance "
                             "numbers and ports unchanged); 0 = one per "
                             f"{VEHICLES_PER_PROCESS} vehicles")
    parser.add_argument("--airframe", choices=AIRFRAME_NAMES, default="quad")
    parser.add_argument("--api-port", type=int, default=SITL_API_REMOTE_PORT,
                        help="remote API port of instance 0 (instance i: +i); 0 = none")
    parser.add_argument("--gcs-port", type=int, default=SITL_GCS_REMOTE_PORT,
                        help="remote GCS port shared by all instances; 0 = none")
    parser.add_argument("--api-local-port", type=int, default=SITL_API_LOCAL_PORT,
                        help="local API port of instance 0 (instance i: +i); 0 = ephemeral")
    parser.add_argument("--gcs-local-port", type=int, default=SITL_GCS_LOCAL_PORT,
                        help="local GCS port of instance 0 (instance i: +i); 0 = ephemeral")
    parser.add_argument("--host", default="127.0.0.1", help="address to bind and send to")
    parser.add_argument("--speed", type=float, default=1.0, help="sim time / wall time")
    parser.add_argument("--fast-forward-speed", type=float, default=FAST_FORWARD_SPEED,
                        help="sim time / wall time from a SIGUSR1 until a SIGUSR2, which "
                             "goes back to --speed (e.g. a take-off flown fast, then the "
                             "rest in real time)")
    parser.add_argument("--ready-json", action="store_true",
                        help="print one JSON line with the bound ports once ready")
    parser.add_argument("--exit-on-stdin-eof", action="store_true",
                        help="stop when stdin reaches end of file")
    parser.add_argument("--signing-dir", type=Path, default=None,
                        help="MAVLink signing keys: instance i keeps its key in "
                             "DIR/i/mavlink/mavlink-signing-key.bin (PX4's file, 40 bytes); "
                             "unset: a key set by SETUP_SIGNING lasts until exit")
    return parser


def process_count(count: int, processes: int) -> int:
    """How many processes run ``count`` vehicles: as asked (never more than vehicles), or
    one per VEHICLES_PER_PROCESS."""
    wanted = processes if processes > 0 else math.ceil(count / VEHICLES_PER_PROCESS)
    return max(1, min(wanted, count))


def _ports_for_instance(base: int, first: int) -> int:
    """The local port of the first instance: SITL adds the instance index to the base."""
    return base + first if base else 0


async def serve(args: argparse.Namespace) -> int:
    stop = stop_event(exit_on_stdin_eof=args.exit_on_stdin_eof)
    cluster = SimCluster(
        airframe=args.airframe,
        count=args.count,
        instance=args.instance,
        host=args.host,
        api_port=_ports_for_instance(args.api_port, args.instance) or None,
        gcs_port=args.gcs_port or None,
        api_local_port=_ports_for_instance(args.api_local_port, args.instance),
        gcs_local_port=_ports_for_instance(args.gcs_local_port, args.instance),
        speed=args.speed,
        signing_dir=args.signing_dir,
    )
    loop = asyncio.get_running_loop()
    loop.add_signal_handler(FAST_FORWARD, cluster.pace.set, args.fast_forward_speed)
    loop.add_signal_handler(REAL_PACE, cluster.pace.set, args.speed)
    async with cluster:
        _report_ports(cluster, args)
        await stop.wait()
    return 0


def _report_ports(cluster: SimCluster, args: argparse.Namespace) -> None:
    human = sys.stderr if args.ready_json else sys.stdout
    for inst in cluster.instances:
        api_remote = inst.api_link.remote
        gcs_remote = inst.gcs_link.remote
        print(
            f"sim instance {inst.instance} ({args.airframe}, sysid {inst.sysid}): "
            f"API udp {args.host}:{inst.api_local_port} -> "
            f"{api_remote[1] if api_remote else 'first sender'}, "
            f"GCS udp {args.host}:{inst.gcs_local_port} -> "
            f"{gcs_remote[1] if gcs_remote else 'first sender'}",
            file=human, flush=True,
        )
    if args.ready_json:
        ready = {
            "event": "ready",
            "instances": [
                {"instance": inst.instance, "sysid": inst.sysid,
                 "api_local_port": inst.api_local_port, "gcs_local_port": inst.gcs_local_port}
                for inst in cluster.instances
            ],
        }
        print(json.dumps(ready), flush=True)


def _child_arguments(args: argparse.Namespace, first: int, count: int) -> list[str]:
    """`python -m sim` arguments of one process running instances first..first+count-1:
    the same base ports (each instance still adds its index) and options."""
    return [
        "--instance", str(first), "--count", str(count), "--processes", "1",
        "--airframe", args.airframe, "--host", args.host, "--speed", repr(args.speed),
        "--fast-forward-speed", repr(args.fast_forward_speed),
        "--api-port", str(args.api_port), "--gcs-port", str(args.gcs_port),
        "--api-local-port", str(args.api_local_port),
        "--gcs-local-port", str(args.gcs_local_port),
        "--ready-json", "--exit-on-stdin-eof",
        *(["--signing-dir", str(args.signing_dir)] if args.signing_dir is not None else []),
    ]


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.count < 1:
        print("--count must be at least 1", file=sys.stderr)
        return 2
    for name, speed in (("--speed", args.speed), ("--fast-forward-speed", args.fast_forward_speed)):
        if not 0 < speed < math.inf:
            print(f"{name} must be positive", file=sys.stderr)
            return 2
    if args.processes < 0:
        print("--processes must be 0 (automatic) or more", file=sys.stderr)
        return 2
    processes = process_count(args.count, args.processes)
    try:
        if processes > 1:
            return asyncio.run(run_processes(args, processes, _child_arguments,
                                             forwarded=(FAST_FORWARD, REAL_PACE)))
        return asyncio.run(serve(args))
    except (OSError, RuntimeError) as exc:
        print(f"sim: {exc}", file=sys.stderr)
        return 1
