"""The 10 m square with the asyncio client, printing the vehicle's events as they come.

    skyhelm serve                      # prints  SkyHelm ready: http://127.0.0.1:8000/?token=...
    python examples/fly_square_async.py 'http://127.0.0.1:8000/?token=...'

One task watches the telemetry socket (mode changes, command results, control events and
the vehicle's messages) while the flight waits for each corner of the square on the state.
The lease is given back however the script ends, as in fly_square.py.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib

from skyhelm_client import AsyncSkyHelm, PositionNed, SkyHelmError

SIDE_M = 10.0
ALTITUDE_M = 5.0
ARRIVED_M = 0.5


async def watch(sky: AsyncSkyHelm) -> None:
    async with contextlib.aclosing(sky.telemetry(rate_hz=1.0)) as messages:
        async for message in messages:
            if message.type == "event":
                print(f"  event {message.kind}: {message.data.get('data')}")
            elif message.type == "statustext":
                print(f"  vehicle says: {message.data.get('text')}")


async def fly_square(sky: AsyncSkyHelm) -> None:
    await sky.acquire(client_name="fly_square_async")
    # a vehicle just started refuses to arm until its estimator has a position
    await sky.wait_until(lambda s: s.ready_to_fly, timeout_s=120, what="ready to fly")
    await sky.arm()
    await sky.takeoff(altitude_m=ALTITUDE_M)
    state = await sky.wait_until(
        lambda s: s.altitude_m > ALTITUDE_M - 0.5, timeout_s=60, what="the take-off altitude"
    )
    here = state.position_ned
    await sky.offboard_start(
        PositionNed(north_m=here.north_m, east_m=here.east_m, down_m=-ALTITUDE_M)
    )
    for dn, de in ((SIDE_M, 0.0), (SIDE_M, SIDE_M), (0.0, SIDE_M), (0.0, 0.0)):
        north_m, east_m = here.north_m + dn, here.east_m + de
        await sky.set_setpoint(PositionNed(north_m=north_m, east_m=east_m, down_m=-ALTITUDE_M))
        await sky.wait_until(
            lambda s: s.position_ned.horizontal_distance_m(north_m, east_m) < ARRIVED_M,  # noqa: B023
            timeout_s=60,
            what=f"north {north_m:.0f} m, east {east_m:.0f} m",
        )
        print(f"at north {north_m:.0f} m, east {east_m:.0f} m")
    await sky.rtl()
    await sky.wait_until(lambda s: not s.armed, timeout_s=120, what="landing and disarm")
    print("landed")
    await sky.release()


async def main(url: str, vehicle: int) -> None:
    async with AsyncSkyHelm(url, vehicle=vehicle) as sky:
        watcher = asyncio.create_task(watch(sky))
        try:
            await fly_square(sky)
        except SkyHelmError as error:
            raise SystemExit(f"refused: {error}") from error
        finally:
            watcher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await watcher


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("url", help="the URL `skyhelm serve` printed (with ?token=)")
    parser.add_argument("--vehicle", type=int, default=1)
    args = parser.parse_args()
    asyncio.run(main(args.url, args.vehicle))
