"""Fly a 10 m square in offboard mode through the SkyHelm API, then return and land.

    skyhelm serve                      # prints  SkyHelm ready: http://127.0.0.1:8000/?token=...
    python examples/fly_square.py 'http://127.0.0.1:8000/?token=...'

The WebSocket control session holds the control lease (heartbeat every 0.5 s); commands and
setpoints go over REST with the same lease id. If this script dies, the server's deadman
holds the vehicle where it is.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
from typing import Any
from urllib.parse import parse_qs, urlsplit

import httpx
from websockets.asyncio.client import ClientConnection, connect

SIDE_M = 10.0
ALTITUDE_M = 5.0
ARRIVED_M = 0.5


class Pilot:
    def __init__(self, base: str, token: str, vehicle_id: int, lease_id: str) -> None:
        self.state_url = f"{base}/api/v1/vehicles/{vehicle_id}"
        self.http = httpx.AsyncClient(
            base_url=f"{base}/api/v1/vehicles/{vehicle_id}",
            timeout=30.0,
            headers={"Authorization": f"Bearer {token}", "X-Lease-Id": lease_id},
        )

    async def command(self, path: str, body: dict[str, Any] | None = None) -> dict[str, Any]:
        response = await self.http.post(path, json=body or {})
        answer: dict[str, Any] = response.json()
        if response.status_code != 200:
            raise SystemExit(f"{path} refused ({response.status_code}): {answer}")
        print(f"{path}: {answer['result']} in {answer['elapsed_ms']:.0f} ms")
        return answer

    async def state(self) -> dict[str, Any]:
        state: dict[str, Any] = (await self.http.get(self.state_url)).json()
        return state

    async def wait_until(self, done: Any, what: str, timeout_s: float = 60.0) -> dict[str, Any]:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while loop.time() < deadline:
            state = await self.state()
            if done(state):
                return state
            await asyncio.sleep(0.2)
        raise SystemExit(f"timed out waiting for {what}")

    async def fly_to(self, north_m: float, east_m: float) -> None:
        target = {
            "type": "position_ned",
            "north_m": north_m,
            "east_m": east_m,
            "down_m": -ALTITUDE_M,
        }
        response = await self.http.put("setpoint", json=target)
        if response.status_code != 200:
            raise SystemExit(f"setpoint refused: {response.json()}")

        def arrived(state: dict[str, Any]) -> bool:
            p = state["position_ned"]
            return math.hypot(p["north_m"] - north_m, p["east_m"] - east_m) < ARRIVED_M

        await self.wait_until(arrived, f"({north_m}, {east_m})")
        print(f"at north {north_m:.0f} m, east {east_m:.0f} m")


async def heartbeat(ws: ClientConnection) -> None:
    while True:
        await ws.send(json.dumps({"type": "heartbeat"}))
        await asyncio.sleep(0.5)


async def drain(ws: ClientConnection) -> None:
    async for text in ws:
        message = json.loads(text)
        if message.get("type") == "lease" and "state" in message:
            print(f"control lease {message['state']}")


async def main(url: str) -> None:
    parts = urlsplit(url)
    token = parse_qs(parts.query)["token"][0]
    base = f"{parts.scheme}://{parts.netloc}"
    async with httpx.AsyncClient(headers={"Authorization": f"Bearer {token}"}) as http:
        vehicles = (await http.get(f"{base}/api/v1/vehicles")).json()
    vehicle_id = vehicles[0]["id"]
    ws_url = f"ws://{parts.netloc}/api/v1/ws/control?vehicle={vehicle_id}&token={token}"
    async with connect(ws_url + "&client_name=fly_square") as ws:
        lease = json.loads(await ws.recv())
        print(f"control of vehicle {vehicle_id}, lease ttl {lease['ttl_s']} s")
        background = [asyncio.create_task(heartbeat(ws)), asyncio.create_task(drain(ws))]
        pilot = Pilot(base, token, vehicle_id, lease["lease_id"])
        try:
            await pilot.command("arm")
            await pilot.command("takeoff", {"altitude_m": ALTITUDE_M})
            await pilot.wait_until(
                lambda s: -s["position_ned"]["down_m"] > ALTITUDE_M - 0.5, "takeoff"
            )
            here = (await pilot.state())["position_ned"]
            n0, e0 = here["north_m"], here["east_m"]
            start = {"type": "position_ned", "north_m": n0, "east_m": e0, "down_m": -ALTITUDE_M}
            await pilot.command("offboard/start", {"setpoint": start})
            for dn, de in ((SIDE_M, 0.0), (SIDE_M, SIDE_M), (0.0, SIDE_M), (0.0, 0.0)):
                await pilot.fly_to(n0 + dn, e0 + de)
            await pilot.command("rtl")
            await pilot.wait_until(lambda s: not s["armed"], "landing and disarm", 120.0)
            print("landed")
        finally:
            for task in background:
                task.cancel()
            await pilot.http.aclose()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url", help="the URL `skyhelm serve` printed (with ?token=)")
    asyncio.run(main(parser.parse_args().url))
