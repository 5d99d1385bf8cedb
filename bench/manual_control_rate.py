"""MANUAL_CONTROL rate as the vehicle sees it, whatever the pilot's rate.

The simulated vehicle (in this process, real time) timestamps every MANUAL_CONTROL it takes
(its 250 Hz loop shares the event loop, so arrivals bunch when the loop is late: the sender's
own intervals are reported beside them);
SkyHelm's link sends sticks that change at 8, 25 and 60 Hz (a slow script, a page, a fast
gamepad poll). Goal: 25 Hz (QGroundControl's rate) on the vehicle's side in every case,
median interval 40 ms and no gap > 100 ms. Changed sticks go out at once in place of the
next tick (bench/input_latency.py measures how soon), so an interval under 20 ms ("bursts")
is a change sent early, and the interval after it up to two periods: the rate stays.

    .venv/bin/python -m bench.manual_control_rate [--seconds 10]
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import math
import os
import statistics
from typing import Any

from bench._results import machine_info, write_results
from server.link import Link, Sticks
from sim.flight.manual_control import StickSample
from sim.process.runner import SimCluster

PILOT_RATES_HZ = (8.0, 25.0, 60.0)
BURST_S = 0.020
GAP_S = 0.100


def figures(arrivals: list[float], pilot_rate_hz: float) -> dict[str, Any]:
    intervals = sorted(b - a for a, b in itertools.pairwise(arrivals))
    return {
        "pilot_rate_hz": pilot_rate_hz,
        "received": len(arrivals),
        "rate_hz": len(intervals) / (arrivals[-1] - arrivals[0]),
        "interval_p50_ms": statistics.median(intervals) * 1e3,
        "interval_p99_ms": intervals[min(len(intervals) - 1, math.ceil(0.99 * len(intervals)) - 1)]
        * 1e3,
        "interval_max_ms": intervals[-1] * 1e3,
        "bursts_under_20ms": sum(i < BURST_S for i in intervals),
        "gaps_over_100ms": sum(i > GAP_S for i in intervals),
    }


async def run(seconds: float) -> dict[str, Any]:
    load_before = os.getloadavg()
    loop = asyncio.get_running_loop()
    arrivals: list[float] = []
    async with SimCluster(airframe="quad", count=1, speed=1.0) as sim:
        await sim.wait_ready(timeout_s=30.0)
        commander = sim.instances[0].vehicle.commander
        take = commander.on_manual_control

        def recording(sample: StickSample, now_s: float) -> None:
            arrivals.append(loop.time())
            take(sample, now_s)

        commander.on_manual_control = recording  # type: ignore[method-assign]
        link = await Link.open(f"udpout:127.0.0.1:{sim.instances[0].api_local_port}",
                               name="bench-sticks")
        try:
            vehicle = await asyncio.wait_for(link.subscribe_vehicles().get(), 10.0)
            results = []
            for pilot_rate_hz in PILOT_RATES_HZ:
                arrivals.clear()
                end = loop.time() + seconds
                k = 0
                while loop.time() < end:
                    # a stick swept back and forth, so every update differs
                    vehicle.manual_control.set_sticks(Sticks(pitch=math.sin(k / 10.0)))
                    k += 1
                    await asyncio.sleep(1.0 / pilot_rate_hz)
                result = figures(list(arrivals), pilot_rate_hz)
                sent = vehicle.manual_control.stats()
                result["sent_side"] = {"rate_hz": sent.rate_hz, "sent": sent.sent,
                                       "interval_p99_ms": sent.interval_p99_ms,
                                       "max_gap_ms": sent.max_gap_ms}
                results.append(result)
                vehicle.manual_control.stop("bench")
                await asyncio.sleep(0.2)
        finally:
            await link.close()
    for r in results:
        print(f"pilot {r['pilot_rate_hz']:>4.0f} Hz -> vehicle {r['rate_hz']:5.2f} Hz, "
              f"p50 {r['interval_p50_ms']:5.1f} ms, p99 {r['interval_p99_ms']:5.1f} ms, "
              f"max {r['interval_max_ms']:5.1f} ms, bursts {r['bursts_under_20ms']}, "
              f"gaps {r['gaps_over_100ms']} "
              f"(sent: p99 {r['sent_side']['interval_p99_ms']:5.1f} ms)")
    return {"seconds_per_rate": seconds, "results": results,
            "machine": machine_info(load_before)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    write_results("manual_control_rate", asyncio.run(run(args.seconds)))


if __name__ == "__main__":
    main()
