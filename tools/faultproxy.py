"""A fault-injecting UDP proxy between SkyHelm and a vehicle: a bad radio on demand.

It relays like a pair of telemetry radios: the vehicle sends to the proxy's *vehicle-facing*
socket, SkyHelm sends to its *server-facing* socket, and each datagram leaves through the
other socket, so each side sees the proxy as its peer::

    SkyHelm  <->  [server-facing | FaultProxy | vehicle-facing]  <->  vehicle

Per direction (``to_vehicle``: SkyHelm's frames towards the vehicle; ``to_server``: the
vehicle's frames towards SkyHelm) it can drop (loss %, independently per datagram or in
bursts as a radio loses them: a Gilbert–Elliott channel with ``burst_frames`` mean burst),
delay (+ jitter), duplicate, reorder (hold one datagram back until the next one has gone)
and corrupt (flip bits); it can cut the link for N seconds in one or both directions (a
partition), or drop only the frames of some message ids for N seconds (``drop_messages``:
the HEARTBEATs alone, say). Every datagram is
counted per direction; see :class:`DirectionCounters` for how the counters add up. The random
choices come from a seeded RNG per direction, so a run is repeatable.

Loopback only: every address it binds or sends to must be a loopback address.

From a test (asyncio)::

    async with FaultProxy(vehicle=("127.0.0.1", sim_port), seed=1) as proxy:
        link = await Link.open(f"udpout:127.0.0.1:{proxy.server_facing_address[1]}")
        proxy.configure(Faults(loss_pct=20))               # both directions
        proxy.configure(Faults(delay_ms=50), "to_vehicle")  # live, one direction
        proxy.partition(5.0)                                # both ways, for 5 s
        proxy.drop_messages({0}, 3.6, "to_server")          # the vehicle's HEARTBEATs
        print(proxy.counters())

From a shell (a bench tool; PX4 SITL instance 0 sends to 14540, answers on 14580)::

    python -m tools.faultproxy --vehicle-listen 127.0.0.1:14540 --vehicle 127.0.0.1:14580 \
        --listen 127.0.0.1:14640 --loss 20 --seed 1
    skyhelm serve --connect udpout:127.0.0.1:14640
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import dataclasses
import functools
import ipaddress
import json
import random
import signal
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

Address = tuple[str, int]
Direction = Literal["to_vehicle", "to_server"]
DirectionChoice = Literal["to_vehicle", "to_server", "both"]
DIRECTIONS: tuple[Direction, Direction] = ("to_vehicle", "to_server")
# A datagram held back for reordering is released after the next one, or after this long
# when no next one comes (so a quiet link does not keep it forever).
REORDER_MAX_HOLD_S = 0.05
MAVLINK1_STX, MAVLINK2_STX = 0xFE, 0xFD
MAVLINK_MSG_ID_HEARTBEAT = 0
# A tap sees every datagram the proxy sends: (direction, payload).
Tap = Callable[[Direction, bytes], None]


@dataclass(frozen=True)
class Faults:
    """What one direction of the proxy does to the datagrams crossing it.

    Probabilities are in percent (0-100) and drawn independently per datagram.
    """

    loss_pct: float = 0.0
    # 0: each datagram lost on its own with loss_pct; > 0: losses come in bursts of this
    # mean length (datagrams), loss_pct of them in the long run (a Gilbert–Elliott channel
    # whose bad state loses every datagram and lasts burst_frames on average)
    burst_frames: float = 0.0
    delay_ms: float = 0.0
    # each datagram's delay is delay_ms + uniform(-jitter_ms, +jitter_ms), never below 0
    jitter_ms: float = 0.0
    duplicate_pct: float = 0.0
    reorder_pct: float = 0.0
    corrupt_pct: float = 0.0
    # bits flipped in a corrupted datagram (at random positions)
    corrupt_bits: int = 1

    def __post_init__(self) -> None:
        for name in ("loss_pct", "duplicate_pct", "reorder_pct", "corrupt_pct"):
            value = getattr(self, name)
            if not 0.0 <= value <= 100.0:
                raise ValueError(f"{name} must be within 0..100, got {value}")
        for name in ("delay_ms", "jitter_ms"):
            if getattr(self, name) < 0.0:
                raise ValueError(f"{name} must not be negative")
        if self.corrupt_bits < 1:
            raise ValueError("corrupt_bits must be at least 1")
        if self.burst_frames and (self.burst_frames < 1.0 or self.loss_pct >= 100.0):
            raise ValueError("burst_frames must be 0 or at least 1, with loss_pct below 100")

    def good_to_bad(self) -> float:
        """The Gilbert–Elliott chance per datagram of a burst starting: its bad state lasts
        burst_frames on average (leaves with 1 / burst_frames), and the share of time in it
        is the loss: p / (p + r) = loss."""
        leave = 1.0 / self.burst_frames
        loss = self.loss_pct / 100.0
        return leave * loss / (1.0 - loss)


NO_FAULTS = Faults()


@dataclass
class DirectionCounters:
    """Datagrams through one direction.

    ``in`` arrived; ``dropped`` were discarded (by loss, by a partition or by message id;
    ``partitioned`` and ``filtered`` are those shares); each survivor goes out once, plus
    once more if ``duplicated``.
    ``corrupted`` had bits flipped, ``delayed`` were held for a delay, ``reordered`` were held
    back and overtaken by a later one (one whose hold ran out first goes in order, uncounted).
    Once nothing is in flight (``pending`` 0):
    ``out == in - dropped + duplicated``.
    """

    in_: int = 0
    dropped: int = 0
    partitioned: int = 0
    filtered: int = 0
    duplicated: int = 0
    corrupted: int = 0
    delayed: int = 0
    reordered: int = 0
    out: int = 0
    bytes_in: int = 0
    bytes_out: int = 0
    # sent with nowhere to go (the far side has not spoken yet and has no fixed address)
    unroutable: int = 0
    pending: int = 0

    def as_dict(self) -> dict[str, int]:
        values = dataclasses.asdict(self)
        values["in"] = values.pop("in_")
        return values


@dataclass
class _Partition:
    until: float = 0.0  # loop time; 0 = not partitioned

    def active(self, now: float) -> bool:
        return now < self.until


@dataclass
class _Lane:
    """One direction: its faults, RNG, counters and the datagram held for reordering."""

    direction: Direction
    rng: random.Random
    faults: Faults = NO_FAULTS
    counters: DirectionCounters = field(default_factory=DirectionCounters)
    partition: _Partition = field(default_factory=_Partition)
    held: bytes | None = None
    held_timer: asyncio.TimerHandle | None = None
    in_burst: bool = False  # the Gilbert–Elliott state: in a burst of losses
    # message id -> loop time until which its frames are dropped
    dropped_ids: dict[int, float] = field(default_factory=dict)


class _Socket(asyncio.DatagramProtocol):
    def __init__(self, on_datagram: Callable[[bytes, Address], None]) -> None:
        self._on_datagram = on_datagram

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self._on_datagram(data, (addr[0], addr[1]))

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable while the far side is not up: a radio does not care either.
        pass


def require_loopback(address: Address, what: str) -> Address:
    """Refuse any address that is not loopback (the proxy is a test and bench tool)."""
    host = address[0]
    if host != "localhost":
        try:
            loopback = ipaddress.ip_address(host).is_loopback
        except ValueError:
            loopback = False
        if not loopback:
            raise ValueError(f"{what} {host!r} is not a loopback address")
    return address


class FaultProxy:
    """A UDP relay with injected faults; see the module docstring.

    ``vehicle``/``server``: where to send each direction. Left as None, the proxy answers the
    last address that spoke to that socket (as ``udpin:`` does), so a vehicle that sends
    first or a server that connects with ``udpout:`` needs no address here.
    ``vehicle_listen``/``listen``: the vehicle-facing and server-facing bind addresses
    (port 0: ephemeral; read :attr:`vehicle_facing_address`/:attr:`server_facing_address`).
    """

    def __init__(
        self,
        *,
        vehicle: Address | None = None,
        server: Address | None = None,
        vehicle_listen: Address = ("127.0.0.1", 0),
        listen: Address = ("127.0.0.1", 0),
        seed: int = 0,
    ) -> None:
        self._fixed: dict[Direction, Address | None] = {
            "to_vehicle": require_loopback(vehicle, "vehicle") if vehicle else None,
            "to_server": require_loopback(server, "server") if server else None,
        }
        self._binds: dict[Direction, Address] = {
            # a datagram going to the vehicle leaves through the vehicle-facing socket
            "to_vehicle": require_loopback(vehicle_listen, "vehicle_listen"),
            "to_server": require_loopback(listen, "listen"),
        }
        self._learned: dict[Direction, Address | None] = {"to_vehicle": None, "to_server": None}
        self._lanes: dict[Direction, _Lane] = {
            d: _Lane(d, random.Random(f"{seed}:{d}")) for d in DIRECTIONS
        }
        self._sockets: dict[Direction, asyncio.DatagramTransport] = {}
        self._timers: set[asyncio.TimerHandle] = set()
        self._taps: list[Tap] = []
        self._arrival_taps: list[Tap] = []
        self._loop: asyncio.AbstractEventLoop | None = None

    # -- life cycle -------------------------------------------------------------------------

    async def start(self) -> FaultProxy:
        loop = asyncio.get_running_loop()
        self._loop = loop
        for direction in DIRECTIONS:
            # what arrives on this socket goes the other way
            on_datagram = functools.partial(self._received, _other(direction))
            transport, _ = await loop.create_datagram_endpoint(
                functools.partial(_Socket, on_datagram), local_addr=self._binds[direction]
            )
            self._sockets[direction] = transport
        return self

    async def stop(self) -> None:
        """Close both sockets; datagrams still delayed or held are discarded (and no longer
        counted as pending)."""
        for timer in self._timers:
            timer.cancel()
        self._timers.clear()
        for lane in self._lanes.values():
            if lane.held_timer is not None:
                lane.held_timer.cancel()
            lane.held, lane.held_timer = None, None
            lane.counters.pending = 0
        for transport in self._sockets.values():
            transport.close()
        self._sockets.clear()

    async def __aenter__(self) -> FaultProxy:
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    # -- addresses --------------------------------------------------------------------------

    @property
    def server_facing_address(self) -> Address:
        """Where SkyHelm sends (``udpout:HOST:PORT``)."""
        return self._bound("to_server")

    @property
    def vehicle_facing_address(self) -> Address:
        """Where the vehicle sends (its remote port)."""
        return self._bound("to_vehicle")

    def _bound(self, direction: Direction) -> Address:
        sockname = self._sockets[direction].get_extra_info("sockname")
        return (sockname[0], sockname[1])

    # -- live configuration -----------------------------------------------------------------

    def configure(self, faults: Faults, direction: DirectionChoice = "both") -> None:
        """Replace the faults of one direction or both, effective for the next datagram."""
        for lane in self._select(direction):
            lane.faults = faults

    def faults(self, direction: Direction) -> Faults:
        return self._lanes[direction].faults

    def partition(self, duration_s: float, direction: DirectionChoice = "both") -> None:
        """Drop everything in ``direction`` for ``duration_s`` from now (a longer running
        partition is not shortened)."""
        now = self._now()
        for lane in self._select(direction):
            lane.partition.until = max(lane.partition.until, now + duration_s)

    def drop_messages(
        self, message_ids: set[int], duration_s: float, direction: DirectionChoice = "both"
    ) -> None:
        """Drop only the frames of these MAVLink message ids (one frame per datagram, as PX4
        and SkyHelm send) for ``duration_s`` from now; everything else passes."""
        until = self._now() + duration_s
        for lane in self._select(direction):
            for message_id in message_ids:
                lane.dropped_ids[message_id] = max(lane.dropped_ids.get(message_id, 0.0), until)

    def heal(self, direction: DirectionChoice = "both") -> None:
        """End a partition now."""
        for lane in self._select(direction):
            lane.partition.until = 0.0

    def partitioned(self, direction: Direction) -> bool:
        return self._lanes[direction].partition.active(self._now())

    def add_tap(self, tap: Tap, *, arriving: bool = False) -> None:
        """Call ``tap(direction, payload)`` for every datagram the proxy sends out (with
        ``arriving``: for every datagram that arrives, before any fault)."""
        (self._arrival_taps if arriving else self._taps).append(tap)

    def counters(self) -> dict[Direction, DirectionCounters]:
        """The live counters per direction (the objects themselves, not copies)."""
        return {d: lane.counters for d, lane in self._lanes.items()}

    def stats(self) -> dict[str, dict[str, int]]:
        """The counters as plain dicts, for JSON."""
        return {d: lane.counters.as_dict() for d, lane in self._lanes.items()}

    def _select(self, direction: DirectionChoice) -> list[_Lane]:
        if direction == "both":
            return list(self._lanes.values())
        if direction not in self._lanes:
            raise ValueError(f"direction must be to_vehicle, to_server or both: {direction!r}")
        return [self._lanes[direction]]

    def _now(self) -> float:
        loop = self._loop or asyncio.get_running_loop()
        return loop.time()

    # -- the relay --------------------------------------------------------------------------

    def _received(self, direction: Direction, data: bytes, addr: Address) -> None:
        # whoever speaks to one socket is the address the other direction answers
        self._learned[_other(direction)] = addr
        lane = self._lanes[direction]
        counters = lane.counters
        counters.in_ += 1
        counters.bytes_in += len(data)
        for tap in self._arrival_taps:
            tap(direction, data)
        if lane.partition.active(self._now()):
            counters.dropped += 1
            counters.partitioned += 1
            return
        if lane.dropped_ids and lane.dropped_ids.get(_message_id(data), 0.0) > self._now():
            counters.dropped += 1
            counters.filtered += 1
            return
        faults = lane.faults
        rng = lane.rng
        if faults.loss_pct and _lost(lane, rng):
            counters.dropped += 1
            return
        if faults.corrupt_pct and rng.random() * 100.0 < faults.corrupt_pct:
            data = _flip_bits(data, faults.corrupt_bits, rng)
            counters.corrupted += 1
        copies = 1
        if faults.duplicate_pct and rng.random() * 100.0 < faults.duplicate_pct:
            copies = 2
            counters.duplicated += 1
        reorder = bool(faults.reorder_pct) and rng.random() * 100.0 < faults.reorder_pct
        for _ in range(copies):
            delay_s = _delay_s(faults, rng)
            if delay_s > 0.0:
                counters.delayed += 1
                counters.pending += 1
                self._later(delay_s, self._after_delay, lane, data, reorder)
            else:
                self._pass(lane, data, reorder)

    def _after_delay(self, lane: _Lane, data: bytes, reorder: bool) -> None:
        lane.counters.pending -= 1
        self._pass(lane, data, reorder)

    def _pass(self, lane: _Lane, data: bytes, reorder: bool) -> None:
        """Past loss and delay: hold it back for reordering, or send it (and release the
        datagram held back, which thus arrives after this later one)."""
        if reorder and lane.held is None:
            lane.held = data
            lane.counters.pending += 1
            lane.held_timer = self._later(REORDER_MAX_HOLD_S, self._release_held, lane, False)
            return
        self._send(lane.direction, data)
        self._release_held(lane, True)

    def _release_held(self, lane: _Lane, overtaken: bool) -> None:
        """Send the held datagram; ``overtaken``: a later one went first (it is reordered),
        otherwise its hold ran out with no successor and it goes in order."""
        if lane.held_timer is not None:
            lane.held_timer.cancel()
            self._timers.discard(lane.held_timer)
        held, lane.held, lane.held_timer = lane.held, None, None
        if held is not None:
            lane.counters.pending -= 1
            if overtaken:
                lane.counters.reordered += 1
            self._send(lane.direction, held)

    def _send(self, direction: Direction, data: bytes) -> None:
        counters = self._lanes[direction].counters
        socket = self._sockets.get(direction)
        target = self._fixed[direction] or self._learned[direction]
        if socket is None or target is None:
            counters.unroutable += 1
            return
        socket.sendto(data, target)
        counters.out += 1
        counters.bytes_out += len(data)
        for tap in self._taps:
            tap(direction, data)

    def _later(self, delay_s: float, callback: Callable[..., None], *args: Any) -> (
        asyncio.TimerHandle
    ):
        assert self._loop is not None

        def run() -> None:
            self._timers.discard(handle)
            callback(*args)

        handle = self._loop.call_later(delay_s, run)
        self._timers.add(handle)
        return handle


def _lost(lane: _Lane, rng: random.Random) -> bool:
    faults = lane.faults
    if not faults.burst_frames:
        return rng.random() * 100.0 < faults.loss_pct
    if lane.in_burst:
        lane.in_burst = rng.random() >= 1.0 / faults.burst_frames
    else:
        lane.in_burst = rng.random() < faults.good_to_bad()
    return lane.in_burst


def _message_id(frame: bytes) -> int | None:
    """The message id of a MAVLink 1 or 2 frame, None for anything else."""
    if len(frame) >= 10 and frame[0] == MAVLINK2_STX:
        return int.from_bytes(frame[7:10], "little")
    if len(frame) >= 6 and frame[0] == MAVLINK1_STX:
        return frame[5]
    return None


def _other(direction: Direction) -> Direction:
    return "to_server" if direction == "to_vehicle" else "to_vehicle"


def _delay_s(faults: Faults, rng: random.Random) -> float:
    if not faults.delay_ms and not faults.jitter_ms:
        return 0.0
    jitter = rng.uniform(-faults.jitter_ms, faults.jitter_ms) if faults.jitter_ms else 0.0
    return max(0.0, faults.delay_ms + jitter) / 1000.0


def _flip_bits(data: bytes, bits: int, rng: random.Random) -> bytes:
    if not data:
        return data
    flipped = bytearray(data)
    for position in rng.sample(range(len(data) * 8), min(bits, len(data) * 8)):
        flipped[position // 8] ^= 1 << (position % 8)
    return bytes(flipped)


# -- the command line ---------------------------------------------------------------------


def _address(text: str) -> Address:
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit():
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, got {text!r}")
    try:
        return require_loopback((host or "127.0.0.1", int(port)), "address")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m tools.faultproxy",
        description="Fault-injecting UDP proxy between SkyHelm and a vehicle (loopback only). "
        "Fault options apply to both directions; --up-*/--down-* override one direction "
        "(up: towards the vehicle, down: towards SkyHelm).",
    )
    parser.add_argument("--listen", type=_address, default=("127.0.0.1", 0),
                        help="server-facing bind HOST:PORT (SkyHelm: udpout:HOST:PORT)")
    parser.add_argument("--server", type=_address, default=None,
                        help="SkyHelm's udpin address; default: answer whoever sent last")
    parser.add_argument("--vehicle-listen", type=_address, default=("127.0.0.1", 0),
                        help="vehicle-facing bind HOST:PORT (the vehicle's remote port)")
    parser.add_argument("--vehicle", type=_address, default=None,
                        help="the vehicle's address; default: answer whoever sent last")
    parser.add_argument("--seed", type=int, default=0)
    for prefix, what in (("", "both directions"), ("up-", "towards the vehicle"),
                         ("down-", "towards SkyHelm")):
        group = parser.add_argument_group(f"faults, {what}")
        group.add_argument(f"--{prefix}loss", type=float, metavar="PCT")
        group.add_argument(f"--{prefix}burst", type=float, metavar="FRAMES",
                           help="losses in bursts of this mean length (Gilbert–Elliott)")
        group.add_argument(f"--{prefix}delay", type=float, metavar="MS")
        group.add_argument(f"--{prefix}jitter", type=float, metavar="MS")
        group.add_argument(f"--{prefix}duplicate", type=float, metavar="PCT")
        group.add_argument(f"--{prefix}reorder", type=float, metavar="PCT")
        group.add_argument(f"--{prefix}corrupt", type=float, metavar="PCT")
    parser.add_argument("--corrupt-bits", type=int, default=1)
    parser.add_argument("--partition", type=float, default=0.0, metavar="S",
                        help="cut the link for S seconds ...")
    parser.add_argument("--partition-after", type=float, default=0.0, metavar="S",
                        help="... starting S seconds after start")
    parser.add_argument("--partition-direction", choices=("both", "to_vehicle", "to_server"),
                        default="both")
    parser.add_argument("--drop-heartbeats", type=float, default=0.0, metavar="S",
                        help="drop only the HEARTBEATs towards SkyHelm for S seconds ...")
    parser.add_argument("--drop-heartbeats-after", type=float, default=0.0, metavar="S",
                        help="... starting S seconds after start")
    parser.add_argument("--report-every", type=float, default=5.0, metavar="S",
                        help="print the counters as a JSON line every S seconds (0: never)")
    return parser


_FIELDS = {"loss": "loss_pct", "burst": "burst_frames", "delay": "delay_ms", "jitter": "jitter_ms",
           "duplicate": "duplicate_pct", "reorder": "reorder_pct", "corrupt": "corrupt_pct"}


def faults_from_args(args: argparse.Namespace, prefix: str) -> Faults:
    """The faults of one direction: the shared options, overridden by the prefixed ones."""
    values: dict[str, Any] = {"corrupt_bits": args.corrupt_bits}
    for option, name in _FIELDS.items():
        shared = getattr(args, option)
        own = getattr(args, f"{prefix}{option}")
        chosen = own if own is not None else shared
        if chosen is not None:
            values[name] = chosen
    return Faults(**values)


async def run(args: argparse.Namespace) -> int:
    proxy = FaultProxy(vehicle=args.vehicle, server=args.server,
                       vehicle_listen=args.vehicle_listen, listen=args.listen, seed=args.seed)
    proxy.configure(faults_from_args(args, "up_"), "to_vehicle")
    proxy.configure(faults_from_args(args, "down_"), "to_server")
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    async with proxy:
        print(json.dumps({
            "event": "ready",
            "server_facing": list(proxy.server_facing_address),
            "vehicle_facing": list(proxy.vehicle_facing_address),
            "to_vehicle": dataclasses.asdict(proxy.faults("to_vehicle")),
            "to_server": dataclasses.asdict(proxy.faults("to_server")),
        }), flush=True)
        if args.partition > 0:
            loop.call_later(args.partition_after, proxy.partition, args.partition,
                            args.partition_direction)
        if args.drop_heartbeats > 0:
            loop.call_later(args.drop_heartbeats_after, proxy.drop_messages,
                            {MAVLINK_MSG_ID_HEARTBEAT}, args.drop_heartbeats, "to_server")
        while not stop.is_set():
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), args.report_every or None)
            if args.report_every:
                print(json.dumps({"event": "counters", **proxy.stats()}), flush=True)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        faults_from_args(args, "up_")
        faults_from_args(args, "down_")
    except ValueError as exc:
        print(exc, file=sys.stderr)
        return 2
    return asyncio.run(run(args))


if __name__ == "__main__":
    sys.exit(main())
