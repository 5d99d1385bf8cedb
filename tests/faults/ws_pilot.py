"""A browser tab's control socket in its own process, so a test can kill it (SIGKILL: the
tab is gone, no close frame) or freeze it (SIGSTOP: the laptop sleeps, the socket stays open).

``python -m tests.faults.ws_pilot URL NORTH_M_S RATE_HZ``: connects to the control socket,
sends a live velocity setpoint (hold-to-fly, as the page's keys do) RATE_HZ times a second,
prints ``flying`` once the first one is accepted, and ``sent T`` after each send, T the
monotonic time just before it (the machine's clock, the test's too): a test that freezes the
tab knows when its last input went out, however long a busy machine kept it from running."""

from __future__ import annotations

import asyncio
import json
import sys
import time

from websockets.asyncio.client import connect


async def fly(url: str, north_m_s: float, rate_hz: float) -> None:
    setpoint = {"type": "velocity_ned", "north_m_s": north_m_s, "east_m_s": 0.0,
                "down_m_s": 0.0}
    async with connect(url) as ws:
        lease = json.loads(await ws.recv())
        if lease.get("type") != "lease":
            raise SystemExit(f"no lease: {lease}")

        async def read_answers() -> None:
            announced = False
            async for text in ws:
                answer = json.loads(text)
                if answer.get("request") == "setpoint":
                    if answer["status"] != 200:
                        raise SystemExit(f"setpoint refused: {answer}")
                    if not announced:
                        print("flying", flush=True)
                        announced = True

        reader = asyncio.create_task(read_answers())
        request_id = 0
        while not reader.done():
            request_id += 1
            message = {"type": "setpoint", "id": request_id, "setpoint": setpoint, "live": True}
            sending_s = time.monotonic()
            await ws.send(json.dumps(message))
            print(f"sent {sending_s:.6f}", flush=True)
            await asyncio.sleep(1.0 / rate_hz)
        reader.result()


if __name__ == "__main__":
    asyncio.run(fly(sys.argv[1], float(sys.argv[2]), float(sys.argv[3])))
