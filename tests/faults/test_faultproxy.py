"""The fault-injecting proxy itself: each fault kind does what it says, and its counters
match what the two ends really sent and received."""

from __future__ import annotations

import asyncio
import itertools
import json
import subprocess
import sys
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any, cast

import pytest

from tests.waiting import holds_for, wait_for
from tools.faultproxy import (
    DIRECTIONS,
    Direction,
    DirectionCounters,
    FaultProxy,
    Faults,
    build_parser,
    faults_from_args,
)

ROOT = Path(__file__).resolve().parents[2]


class End(asyncio.DatagramProtocol):
    """One side of the radio link (a stand-in server or vehicle): records what arrives."""

    def __init__(self) -> None:
        self.endpoint: asyncio.DatagramTransport | None = None
        self.received: list[tuple[float, bytes, tuple[str, int]]] = []

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.endpoint = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.received.append((asyncio.get_running_loop().time(), data, (addr[0], addr[1])))

    @property
    def address(self) -> tuple[str, int]:
        assert self.endpoint is not None
        host, port = self.endpoint.get_extra_info("sockname")[:2]
        return (host, port)

    @property
    def payloads(self) -> list[bytes]:
        return [data for _, data, _ in self.received]

    def send(self, data: bytes, to: tuple[str, int]) -> None:
        assert self.endpoint is not None
        self.endpoint.sendto(data, to)


def close_ends(*ends: End) -> None:
    for end in ends:
        assert end.endpoint is not None
        end.endpoint.close()


async def open_end() -> End:
    _, end = await asyncio.get_running_loop().create_datagram_endpoint(
        End, local_addr=("127.0.0.1", 0)
    )
    return end


class Rig:
    def __init__(self, proxy: FaultProxy, server: End, vehicle: End) -> None:
        self.proxy, self.server, self.vehicle = proxy, server, vehicle
        self.sent: dict[Direction, int] = {"to_vehicle": 0, "to_server": 0}

    def up(self, data: bytes) -> None:
        """The server sends towards the vehicle."""
        self.sent["to_vehicle"] += 1
        self.server.send(data, self.proxy.server_facing_address)

    def down(self, data: bytes) -> None:
        """The vehicle sends towards the server."""
        self.sent["to_server"] += 1
        self.vehicle.send(data, self.proxy.vehicle_facing_address)

    async def settle(self) -> None:
        """Until the proxy has had every datagram sent so far, nothing is in flight inside
        it, and every datagram it sent arrived."""
        counters = self.proxy.counters()
        await wait_for(
            lambda: all(counters[d].in_ == n for d, n in self.sent.items()),
            10.0, "every datagram into the proxy",
        )
        await wait_for(
            lambda: all(c.pending == 0 for c in counters.values())
            and len(self.vehicle.received) == counters["to_vehicle"].out
            and len(self.server.received) == counters["to_server"].out,
            10.0, "the proxy to drain",
        )


@pytest.fixture
async def rig() -> AsyncIterator[Rig]:
    server, vehicle = await open_end(), await open_end()
    async with FaultProxy(vehicle=vehicle.address, server=server.address, seed=7) as proxy:
        yield Rig(proxy, server, vehicle)
    close_ends(server, vehicle)


def numbered(n: int, size: int = 40) -> list[bytes]:
    return [i.to_bytes(4, "big") + bytes(size - 4) for i in range(n)]


async def pass_through(
    rig: Rig, faults: Faults, direction: Direction, count: int
) -> tuple[list[bytes], DirectionCounters]:
    """Sets one direction's faults, sends `count` numbered datagrams that way and waits for
    the proxy to settle: what was sent, and that direction's counters."""
    rig.proxy.configure(faults, direction)
    sent = numbered(count)
    await send_all(rig, direction, sent)
    counters = rig.proxy.counters()[direction]
    await rig.settle()
    return sent, counters


async def latencies_s(rig: Rig, direction: Direction, count: int) -> list[float]:
    """Sends `count` numbered datagrams one way at once and, once the proxy has settled,
    the time each took to arrive, in the order they arrived."""
    send, end = (rig.up, rig.vehicle) if direction == "to_vehicle" else (rig.down, rig.server)
    loop = asyncio.get_running_loop()
    sent_at = {}
    for data in numbered(count):
        sent_at[data] = loop.time()
        send(data)
    await rig.settle()
    return [t - sent_at[data] for t, data, _ in end.received]


def balanced(counters: Any) -> bool:
    return bool(counters.out == counters.in_ - counters.dropped + counters.duplicated)


async def send_all(rig: Rig, direction: Direction, datagrams: list[bytes]) -> None:
    """Send in small batches, each once the proxy has read the last: a burst larger than a
    socket's receive buffer would be dropped by the kernel, not by the proxy."""
    send = rig.up if direction == "to_vehicle" else rig.down
    counters = rig.proxy.counters()[direction]
    for start in range(0, len(datagrams), 20):
        for data in datagrams[start:start + 20]:
            send(data)
        await wait_for(lambda: counters.in_ == rig.sent[direction], 10.0,
                       "the proxy to read a batch")



async def test_learns_each_side_from_what_it_sends() -> None:
    server, vehicle = await open_end(), await open_end()
    # no fixed addresses: like a radio, each side is answered where it spoke from
    async with FaultProxy(seed=1) as proxy:
        rig = Rig(proxy, server, vehicle)
        rig.down(b"heartbeat nobody hears")  # the server has not spoken yet
        down = proxy.counters()["to_server"]
        await wait_for(lambda: down.unroutable == 1, 5.0, "the first datagram to be unroutable")
        await _relay_both_ways(rig)
        assert (down.in_, down.out, down.unroutable) == (2, 1, 1)
    close_ends(server, vehicle)


async def test_relays_to_fixed_addresses(rig: Rig) -> None:
    await _relay_both_ways(rig)


async def _relay_both_ways(rig: Rig) -> None:
    rig.up(b"from server")
    await wait_for(lambda: rig.vehicle.received, 5.0, "the vehicle to hear the server")
    rig.down(b"from vehicle")
    await wait_for(lambda: rig.server.received, 5.0, "the server to hear the vehicle")
    assert rig.vehicle.received[0][1:] == (b"from server", rig.proxy.vehicle_facing_address)
    assert rig.server.received[0][1:] == (b"from vehicle", rig.proxy.server_facing_address)
    up = rig.proxy.counters()["to_vehicle"]
    assert (up.in_, up.out, up.dropped) == (1, 1, 0)


async def test_loss_drops_its_share_and_the_counters_match_what_arrived(rig: Rig) -> None:
    sent, counters = await pass_through(rig, Faults(loss_pct=20), "to_vehicle", 2000)
    assert counters.dropped + counters.out == len(sent)
    assert len(rig.vehicle.received) == counters.out
    # binomial(2000, 0.2): 400 expected, sd 18; 300..500 is more than 5 sd either way
    assert 300 <= counters.dropped <= 500
    # what arrived is in order and each one once
    arrived = rig.vehicle.payloads
    assert arrived == [d for d in sent if d in set(arrived)]
    assert rig.proxy.counters()["to_server"].in_ == 0


async def test_the_same_seed_drops_the_same_datagrams() -> None:
    patterns = []
    for _ in range(2):
        server, vehicle = await open_end(), await open_end()
        async with FaultProxy(vehicle=vehicle.address, seed=42) as proxy:
            rig = Rig(proxy, server, vehicle)
            proxy.configure(Faults(loss_pct=30))
            await send_all(rig, "to_vehicle", numbered(300))
            await rig.settle()
            patterns.append(vehicle.payloads)
        close_ends(server, vehicle)
    assert patterns[0] == patterns[1]
    assert 0 < len(patterns[0]) < 300


async def test_delay_holds_every_datagram_at_least_that_long(rig: Rig) -> None:
    rig.proxy.configure(Faults(delay_ms=80), "to_server")
    latencies = await latencies_s(rig, "to_server", 20)
    counters = rig.proxy.counters()["to_server"]
    assert (counters.in_, counters.delayed, counters.out) == (20, 20, 20)
    assert min(latencies) >= 0.075
    assert rig.server.payloads == numbered(20)  # a fixed delay keeps the order


async def test_jitter_spreads_the_delays_within_its_bounds(rig: Rig) -> None:
    rig.proxy.configure(Faults(delay_ms=60, jitter_ms=50), "to_vehicle")
    latencies = sorted(await latencies_s(rig, "to_vehicle", 60))
    assert len(latencies) == 60
    assert latencies[0] >= 0.009  # never below delay - jitter
    # really spread, not one fixed delay: sent at once, they arrive in another order (a fixed
    # delay keeps it). The order, not the arrival times: a loop stalled past the delays
    # releases them all at once, yet in the order of their delays.
    arrived = [data for _, data, _ in rig.vehicle.received]
    assert sorted(arrived) == numbered(60)
    assert arrived != numbered(60)
    assert rig.proxy.counters()["to_vehicle"].delayed == 60


async def test_duplication_sends_the_counted_share_twice(rig: Rig) -> None:
    sent, counters = await pass_through(rig, Faults(duplicate_pct=30), "to_vehicle", 500)
    assert 100 <= counters.duplicated <= 200
    assert counters.out == len(sent) + counters.duplicated == len(rig.vehicle.received)
    twice = [d for d in sent if rig.vehicle.payloads.count(d) == 2]
    assert len(twice) == counters.duplicated
    assert set(rig.vehicle.payloads) == set(sent)


async def test_reordering_swaps_a_held_datagram_behind_the_next(rig: Rig) -> None:
    rig.proxy.configure(Faults(reorder_pct=100), "to_server")
    sent = numbered(10)
    for data in sent:
        rig.down(data)
    await rig.settle()
    # every other datagram is held and released after its successor: pairs swap
    expected = [sent[i ^ 1] for i in range(10)]
    assert rig.server.payloads == expected
    assert rig.proxy.counters()["to_server"].reordered == 5


async def test_a_held_datagram_is_released_when_no_successor_comes(rig: Rig) -> None:
    rig.proxy.configure(Faults(reorder_pct=100), "to_server")
    rig.down(b"alone")
    await rig.settle()
    assert rig.server.payloads == [b"alone"]


async def test_partial_reordering_keeps_every_datagram(rig: Rig) -> None:
    sent, counters = await pass_through(rig, Faults(reorder_pct=25), "to_vehicle", 400)
    arrived = rig.vehicle.payloads
    assert sorted(arrived) == sent
    out_of_order = sum(1 for a, b in itertools.pairwise(arrived) if a > b)
    assert out_of_order == counters.reordered
    assert 30 <= counters.reordered <= 110


async def test_corruption_flips_the_counted_bits(rig: Rig) -> None:
    faults = Faults(corrupt_pct=50, corrupt_bits=3)
    sent, counters = await pass_through(rig, faults, "to_server", 200)
    flipped = [
        sum(bin(a ^ b).count("1") for a, b in zip(original, got, strict=True))
        for original, got in zip(sent, rig.server.payloads, strict=True)
    ]
    assert sum(1 for bits in flipped if bits) == counters.corrupted
    assert set(flipped) == {0, 3}
    assert 60 <= counters.corrupted <= 140


async def test_a_one_way_partition_cuts_only_that_way_until_healed(rig: Rig) -> None:
    rig.proxy.partition(60.0, "to_vehicle")
    assert rig.proxy.partitioned("to_vehicle")
    assert not rig.proxy.partitioned("to_server")
    for data in numbered(5):
        rig.up(data)
        rig.down(data)
    await wait_for(lambda: len(rig.server.received) == 5, 5.0, "the open direction to pass")
    up = rig.proxy.counters()["to_vehicle"]
    await wait_for(lambda: up.in_ == 5, 5.0, "the cut direction's datagrams to reach the proxy")
    assert (up.dropped, up.partitioned, up.out) == (5, 5, 0)
    assert rig.vehicle.received == []
    rig.proxy.heal()
    rig.up(b"after heal")
    await wait_for(lambda: rig.vehicle.payloads == [b"after heal"], 5.0, "traffic after heal")


async def test_a_partition_ends_by_itself_after_its_duration(rig: Rig) -> None:
    rig.proxy.partition(0.3)
    rig.up(b"lost")
    up = rig.proxy.counters()["to_vehicle"]
    await wait_for(lambda: up.partitioned == 1, 5.0, "the datagram dropped by the partition")
    await wait_for(lambda: not rig.proxy.partitioned("to_vehicle"), 5.0, "the partition to end")
    assert not rig.proxy.partitioned("to_server")
    rig.up(b"through")
    rig.down(b"back")
    await wait_for(lambda: rig.vehicle.payloads == [b"through"], 5.0, "traffic to pass again")
    await wait_for(lambda: rig.server.payloads == [b"back"], 5.0, "traffic to pass back")


async def test_faults_change_live_between_datagrams(rig: Rig) -> None:
    rig.up(b"before")
    await wait_for(lambda: len(rig.vehicle.received) == 1, 5.0, "a clean datagram")
    rig.proxy.configure(Faults(loss_pct=100))
    rig.up(b"dropped")
    counters = rig.proxy.counters()["to_vehicle"]
    await wait_for(lambda: counters.dropped == 1, 5.0, "the datagram to be dropped")
    rig.proxy.configure(Faults())
    rig.up(b"after")
    await wait_for(lambda: len(rig.vehicle.received) == 2, 5.0, "traffic to pass again")
    await holds_for(lambda: len(rig.vehicle.received) == 2, 0.1, "nothing else arrives")
    assert rig.vehicle.payloads == [b"before", b"after"]


async def test_every_fault_at_once_keeps_the_counters_balanced(rig: Rig) -> None:
    faults = Faults(loss_pct=10, delay_ms=5, jitter_ms=5, duplicate_pct=10, reorder_pct=10,
                    corrupt_pct=10)
    rig.proxy.configure(faults)
    sent = numbered(600)
    await asyncio.gather(send_all(rig, "to_vehicle", sent), send_all(rig, "to_server", sent))
    await rig.settle()
    counters = rig.proxy.counters()
    for direction in DIRECTIONS:
        c = counters[direction]
        assert balanced(c), rig.proxy.stats()
        assert min(c.dropped, c.duplicated, c.reordered, c.corrupted) > 0, rig.proxy.stats()
        assert c.delayed == c.in_ - c.dropped + c.duplicated
    assert len(rig.vehicle.received) == counters["to_vehicle"].out
    assert len(rig.server.received) == counters["to_server"].out


def test_addresses_off_loopback_are_refused() -> None:
    with pytest.raises(ValueError, match="not a loopback"):
        FaultProxy(vehicle=("10.0.0.1", 5000))
    with pytest.raises(ValueError, match="not a loopback"):
        FaultProxy(listen=("0.0.0.0", 0))


def test_out_of_range_faults_are_refused() -> None:
    with pytest.raises(ValueError, match="loss_pct"):
        Faults(loss_pct=120)
    with pytest.raises(ValueError, match="delay_ms"):
        Faults(delay_ms=-1)


def test_the_command_line_gives_each_direction_its_faults() -> None:
    args = build_parser().parse_args(["--loss", "20", "--down-loss", "5", "--up-delay", "30"])
    assert faults_from_args(args, "up_") == Faults(loss_pct=20, delay_ms=30)
    assert faults_from_args(args, "down_") == Faults(loss_pct=5)


async def test_the_command_line_tool_relays_with_its_faults() -> None:
    server, vehicle = await open_end(), await open_end()
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "tools.faultproxy", "--vehicle", f"127.0.0.1:{vehicle.address[1]}",
        "--up-loss", "100", "--report-every", "0.2",
        cwd=ROOT, stdout=asyncio.subprocess.PIPE,
    )
    try:
        assert process.stdout is not None
        ready = json.loads(await asyncio.wait_for(process.stdout.readline(), 30.0))
        assert ready["event"] == "ready"
        assert ready["to_vehicle"]["loss_pct"] == 100
        server.send(b"dropped", tuple(ready["server_facing"]))
        vehicle.send(b"passes", tuple(ready["vehicle_facing"]))
        await wait_for(lambda: server.payloads == [b"passes"], 10.0, "the vehicle's datagram")
        while True:
            line = json.loads(await asyncio.wait_for(process.stdout.readline(), 10.0))
            if line["to_vehicle"]["in"] == 1:
                break
        assert line["to_vehicle"]["dropped"] == 1
        assert line["to_server"]["out"] == 1
        assert vehicle.received == []
    finally:
        process.terminate()
        assert await asyncio.wait_for(process.wait(), 10.0) == 0
        close_ends(server, vehicle)


def test_the_command_line_tool_refuses_a_remote_address() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "tools.faultproxy", "--vehicle", "192.0.2.1:5000"],
        cwd=ROOT, capture_output=True, text=True, timeout=30,
    )
    assert result.returncode == 2
    assert "loopback" in result.stderr


@pytest.mark.parametrize("loss_pct", [10.0, 20.0, 40.0])
async def test_burst_loss_comes_in_bursts_of_the_mean_length_at_the_asked_share(
    rig: Rig, loss_pct: float
) -> None:
    sent, counters = await pass_through(
        rig, Faults(loss_pct=loss_pct, burst_frames=5.0), "to_server", 6000)
    arrived = set(rig.server.payloads)
    lost = [data not in arrived for data in sent]
    bursts = [len(list(run)) for is_lost, run in itertools.groupby(lost) if is_lost]
    share_pct = 100.0 * sum(lost) / len(sent)
    mean_burst = sum(bursts) / len(bursts)
    # a Markov chain mixes slower than independent draws: wide but telling bounds (the
    # independent loss of the same share would give bursts of 1.1-1.7)
    assert abs(share_pct - loss_pct) <= 0.3 * loss_pct, share_pct
    assert 4.0 <= mean_burst <= 6.0, mean_burst
    assert counters.dropped == sum(lost)


async def test_burst_loss_is_refused_without_a_sane_length() -> None:
    with pytest.raises(ValueError, match="burst_frames"):
        Faults(loss_pct=20.0, burst_frames=0.5)
    with pytest.raises(ValueError, match="burst_frames"):
        Faults(loss_pct=100.0, burst_frames=5.0)


def _mavlink2(message_id: int, seq: int) -> bytes:
    header = bytes([0xFD, 9, 0, 0, seq % 256, 1, 1]) + message_id.to_bytes(3, "little")
    return header + bytes(9 + 2)


async def test_dropping_a_message_id_drops_only_those_frames_for_the_time_asked(
    rig: Rig,
) -> None:
    heartbeat_id, attitude_id = 0, 30
    rig.proxy.drop_messages({heartbeat_id}, 0.3, "to_server")
    frames = [_mavlink2(heartbeat_id if i % 5 == 0 else attitude_id, i) for i in range(50)]
    await send_all(rig, "to_server", frames)
    await rig.settle()
    kinds = [int.from_bytes(data[7:10], "little") for data in rig.server.payloads]
    assert kinds.count(attitude_id) == 40
    assert heartbeat_id not in kinds
    counters = rig.proxy.counters()["to_server"]
    assert (counters.filtered, counters.dropped) == (10, 10)
    await asyncio.sleep(0.35)  # the drop ends on its own
    rig.down(_mavlink2(heartbeat_id, 50))
    await rig.settle()
    assert int.from_bytes(rig.server.payloads[-1][7:10], "little") == heartbeat_id
