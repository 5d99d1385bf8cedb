"""A REST flight written from docs/api.md alone, as a user's script would fly it: plain httpx,
default server settings, one stage per step of the flight. The same stages fly the built-in
sim (tests/api/test_rest_flight.py) and real PX4 SITL (tests/px4/test_px4_rest_flight.py);
the stages themselves are in tests/rest_flight_stages.py.

Each stage asserts what the documentation promises and says what it saw when it did not get
it; a transcript of every call (status, body) and state change is printed, so a failing run
on real PX4 shows PX4's own answers.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from collections.abc import Callable
from typing import Any

import httpx

from skyhelm_client.tls import default_tls
from tests.serve_process import Served
from tests.sim_pace import fast_forwarded
from tests.waiting import holds_for_blocking, wait_for_blocking

Json = dict[str, Any]

CLIENT_NAME = "rest flight"
TAKEOFF_ALT_M = 5.0
# docs/api.md: the default lease outlives a 60 s wait for a takeoff without any renewal.
LEASE_SURVIVES_WAIT_S = 60.0
# docs/api.md: deadman_timeout_s default; a silent live input is braked after it.
DEADMAN_TIMEOUT_S = 1.0
# How often a held key repeats a live setpoint (a keyboard's auto-repeat is 30 ms; slower here).
LIVE_REPEAT_S = 0.2
# docs/api.md: envelope default max_speed_xy_m_s.
MAX_SPEED_XY_M_S = 12.0


class RestFlight:
    """A pilot's REST session against one vehicle, with a transcript of what it saw."""

    def __init__(self, served: Served, vehicle_id: int | None = None) -> None:
        self.served = served
        self.http = httpx.Client(base_url=served.api, timeout=30.0, verify=default_tls())
        self.vehicle_id = vehicle_id
        self.lease_id: str | None = None
        self.transcript: list[str] = []
        self.failed_stage: str | None = None
        self._started = time.monotonic()

    def fast_forwarded(self) -> contextlib.AbstractContextManager[None]:
        """A flight whose end the stage checks, not its pace, at the simulated vehicle's
        fast-forward speed (tests/sim_pace.py); against PX4 at its own."""
        process = self.served.process
        return fast_forwarded(process.pid if process is not None else None)

    # -- talking to the server -------------------------------------------------------------
    def log(self, text: str) -> None:
        line = f"{time.monotonic() - self._started:7.2f}s {text}"
        self.transcript.append(line)
        print(line)

    def headers(self, token: str | None = None, lease: bool = True) -> dict[str, str]:
        result = {"Authorization": f"Bearer {token or self.served.pilot_token}"}
        if lease and self.lease_id:
            result["X-Lease-Id"] = self.lease_id
        return result

    def call(
        self,
        method: str,
        path: str,
        body: Any = None,
        *,
        token: str | None = None,
        lease: bool = True,
        params: dict[str, str] | None = None,
        content: str | None = None,
    ) -> httpx.Response:
        """One call under /vehicles/{id}/ (or an absolute API path starting with /)."""
        url = path if path.startswith("/") else f"/vehicles/{self.vehicle_id}/{path}".rstrip("/")
        headers = self.headers(token, lease)
        if content is not None:
            headers["Content-Type"] = "application/json"
        response = self.http.request(
            method,
            url,
            json=body if content is None else None,
            content=content,
            headers=headers,
            params=params,
        )
        shown = response.text if len(response.text) < 400 else response.text[:400] + "..."
        query = f"?{params}" if params else ""
        self.log(f"{method} {url}{query} -> {response.status_code} {shown}")
        return response

    def expect(self, response: httpx.Response, status: int, what: str) -> Any:
        assert response.status_code == status, (
            f"{what}: expected {status}, got {response.status_code} {response.text}"
        )
        if not response.content:
            return {}
        return response.json()

    def state(self) -> Json:
        response = self.http.get(f"/vehicles/{self.vehicle_id}", headers=self.headers(lease=False))
        assert response.status_code == 200, f"reading the state: {response.text}"
        body: Json = response.json()
        return body

    def wait_state(self, what: str, predicate: Callable[[Json], object], timeout_s: float) -> Json:
        """Poll the state until ``predicate`` holds; the transcript shows each change and the
        failure names the state last seen."""
        start = time.monotonic()
        seen: list[Json] = [{}]
        shown: list[str] = [""]

        def check() -> Json | None:
            seen[0] = state = self.state()
            if (summary := summarize(state)) != shown[0]:
                self.log(f"  state: {summary}")
                shown[0] = summary
            return state if predicate(state) else None

        try:
            wait_for_blocking(what, check, timeout_s)
        except AssertionError:
            raise AssertionError(
                f"{what}: not within {timeout_s} s; last state {summarize(seen[0])}"
            ) from None
        self.log(f"  {what}: after {time.monotonic() - start:.1f} s")
        return seen[0]

    def hold_state(self, what: str, predicate: Callable[[Json], object], duration_s: float) -> None:
        """``predicate`` stays true for ``duration_s`` (a "nothing changes" claim)."""
        seen: list[Json] = [{}]

        def check() -> object:
            seen[0] = self.state()
            return predicate(seen[0])

        try:
            holds_for_blocking(what, check, duration_s)
        except AssertionError:
            raise AssertionError(f"{what}: stopped holding; state {summarize(seen[0])}") from None

    def command(self, path: str, body: Any = None) -> Json:
        """A command the docs promise answers 200 ACCEPTED."""
        answer: Json = self.expect(
            self.call("POST", path, body if body is not None else {}), 200, path
        )
        assert answer.get("result") == "ACCEPTED", f"{path}: {answer}"
        return answer

    def control(self) -> Json:
        status: Json = self.expect(self.call("GET", "control", lease=False), 200, "GET /control")
        return status


def summarize(state: Json) -> str:
    if not state:
        return "(none)"
    pos = state.get("position_ned") or {}
    vel = state.get("velocity_ned") or {}
    setpoint = state.get("setpoint") or {}
    text = [
        f"mode={state.get('mode')}/{state.get('user_mode')}",
        f"armed={state.get('armed')}",
        f"landed={state.get('landed_state')}",
        f"ned=({_f(pos.get('north_m'))},{_f(pos.get('east_m'))},{_f(pos.get('down_m'))})",
        f"v={_f(speed_xy(state))}/{_f(vel.get('down_m_s'))}",
        f"setpoint={setpoint.get('type')}",
        f"stream={(state.get('stream') or {}).get('active')}",
    ]
    texts = [entry.get("text") for entry in state.get("statustext") or []][-2:]
    if texts:
        text.append(f"statustext={texts}")
    return " ".join(text)


def _f(value: Any) -> str:
    return f"{value:.1f}" if isinstance(value, int | float) else str(value)


def alt_rel(state: Json) -> float:
    return float((state.get("global") or {}).get("alt_rel_m") or 0.0)


def speed_xy(state: Json) -> float:
    vel = state.get("velocity_ned") or {}
    return math.hypot(vel.get("north_m_s") or 0.0, vel.get("east_m_s") or 0.0)


def distance_ned(state: Json, north_m: float, east_m: float) -> float:
    pos = state["position_ned"]
    return math.hypot(pos["north_m"] - north_m, pos["east_m"] - east_m)


def position_ned(north_m: float, east_m: float, down_m: float) -> Json:
    return {"type": "position_ned", "north_m": north_m, "east_m": east_m, "down_m": down_m}


def velocity_ned(north_m_s: float, east_m_s: float = 0.0, down_m_s: float = 0.0) -> Json:
    return {
        "type": "velocity_ned",
        "north_m_s": north_m_s,
        "east_m_s": east_m_s,
        "down_m_s": down_m_s,
    }


def in_offboard(state: Json) -> bool:
    return bool(state.get("mode") == "OFFBOARD")


def keep_going() -> bool:
    """SKYHELM_FLIGHT_KEEP_GOING=1 runs every stage after a failure (to record a whole run)."""
    return os.environ.get("SKYHELM_FLIGHT_KEEP_GOING") == "1"
