"""Fly a 10 m square in offboard mode through the SkyHelm API, then return and land.

    skyhelm serve                      # prints  SkyHelm ready: http://127.0.0.1:8000/?token=...
    python examples/fly_square.py 'http://127.0.0.1:8000/?token=...'

Uses the blocking client (`skyhelm_client.SkyHelm`): it takes the control lease, and its
waits renew the lease while they poll, so the script keeps control however long it waits.
However the script ends (the square flown, a refusal, Ctrl-C, SIGTERM) the client gives the
lease back, and the server holds the vehicle where it is; killed outright (SIGKILL), the
server sees the process gone and does the same. The next script takes control without
`force`, and arms from whatever mode this one left the vehicle in.
"""

from __future__ import annotations

import argparse

from skyhelm_client import PositionNed, SkyHelm, SkyHelmError

SIDE_M = 10.0
ALTITUDE_M = 5.0
ARRIVED_M = 0.5


def fly_square(sky: SkyHelm) -> None:
    lease = sky.acquire(client_name="fly_square")
    print(f"control of vehicle {sky.vehicle_id} as {lease.holder}, lease ttl {lease.ttl_s} s")
    # a vehicle just started (PX4 or the simulated one) refuses to arm until its estimator
    # has a position: wait until its arming checks pass
    sky.wait_until(lambda s: s.ready_to_fly, timeout_s=120, what="ready to fly")
    print("arm:", sky.arm().result)
    print("takeoff:", sky.takeoff(altitude_m=ALTITUDE_M).result)
    here = sky.wait_until(
        lambda s: s.altitude_m > ALTITUDE_M - 0.5, timeout_s=60, what="the take-off altitude"
    ).position_ned
    start = PositionNed(north_m=here.north_m, east_m=here.east_m, down_m=-ALTITUDE_M)
    print("offboard:", sky.offboard_start(start).result)
    for dn, de in ((SIDE_M, 0.0), (SIDE_M, SIDE_M), (0.0, SIDE_M), (0.0, 0.0)):
        north_m, east_m = here.north_m + dn, here.east_m + de
        sky.set_setpoint(PositionNed(north_m=north_m, east_m=east_m, down_m=-ALTITUDE_M))
        sky.wait_until(
            lambda s: s.position_ned.horizontal_distance_m(north_m, east_m) < ARRIVED_M,  # noqa: B023
            timeout_s=60,
            what=f"north {north_m:.0f} m, east {east_m:.0f} m",
        )
        print(f"at north {north_m:.0f} m, east {east_m:.0f} m")
    print("rtl:", sky.rtl().result)
    sky.wait_until(lambda s: not s.armed, timeout_s=120, what="landing and disarm")
    print("landed")
    sky.release()


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("url", help="the URL `skyhelm serve` printed (with ?token=)")
    parser.add_argument("--vehicle", type=int, default=1)
    args = parser.parse_args()
    with SkyHelm(args.url, vehicle=args.vehicle) as sky:
        try:
            fly_square(sky)
        except SkyHelmError as error:
            raise SystemExit(f"refused: {error}") from error


if __name__ == "__main__":
    main()
