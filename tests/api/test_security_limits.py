"""Abuse limits: token buckets per token on REST control calls (429 + Retry-After), and the
wrong-token lockout per client address (exponential, recovers, other addresses unaffected).
Virtual clocks drive the buckets and the lockout; no vehicle is needed."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from server.control.auth_lockout import Lockout
from server.control.keyed import PerKey
from server.control.ratelimit import RateLimiter, TokenBucket
from tests.api.conftest import OBSERVER, PILOT, Api, api_for, auth

WEB_DIR = Path(__file__).resolve().parents[2] / "web"


class FakeClock:
    def __init__(self) -> None:
        self.now_s = 1000.0

    def __call__(self) -> float:
        return self.now_s

    def advance(self, seconds: float) -> None:
        self.now_s += seconds


def test_bucket_passes_its_burst_then_refills_at_its_rate() -> None:
    clock = FakeClock()
    bucket = TokenBucket(rate_per_s=10.0, burst=3, clock=clock)
    assert [bucket.take() for _ in range(3)] == [0.0, 0.0, 0.0]
    assert bucket.take() == pytest.approx(0.1)
    clock.advance(0.05)
    assert bucket.take() == pytest.approx(0.05)  # half a call refilled
    clock.advance(0.05)
    assert bucket.take() == 0.0
    clock.advance(60.0)  # never more than the burst
    assert [bucket.take() for _ in range(4)][-1] > 0.0


def test_limiter_keeps_one_bucket_per_key() -> None:
    clock = FakeClock()
    limiter = RateLimiter(1.0, 2, clock)
    assert [limiter.take("pilot") for _ in range(2)] == [0.0, 0.0]
    assert limiter.take("pilot") > 0.0
    assert limiter.take("observer") == 0.0


def test_per_key_state_forgets_the_least_recently_used_key_first() -> None:
    keyed: PerKey[list[int]] = PerKey(list, max_keys=2)
    keyed.use("a").append(1)
    keyed.use("b")
    keyed.use("a")  # now "b" is the least recently used
    keyed.use("c")
    assert keyed.get("b") is None
    assert keyed.get("a") == [1]
    assert keyed.get("c") == []


def test_lockout_backs_off_exponentially_and_forgives_on_success() -> None:
    clock = FakeClock()
    lockout = Lockout(free_failures=3, base_s=1.0, max_s=8.0, clock=clock)
    assert [lockout.failed("a") for _ in range(3)] == [0.0, 0.0, 0.0]
    assert lockout.retry_after_s("a") == 0.0
    locks = []
    for _ in range(6):
        locks.append(lockout.failed("a"))
        assert lockout.retry_after_s("a") == pytest.approx(locks[-1])
        assert lockout.retry_after_s("b") == 0.0
        clock.advance(locks[-1])
        assert lockout.retry_after_s("a") == 0.0
    assert locks == [1.0, 2.0, 4.0, 8.0, 8.0, 8.0]
    lockout.succeeded("a")
    assert lockout.failures("a") == 0
    assert lockout.failed("a") == 0.0


def test_lockout_forgets_a_quiet_address() -> None:
    clock = FakeClock()
    lockout = Lockout(free_failures=1, base_s=1.0, max_s=4.0, clock=clock)
    lockout.failed("a")
    assert lockout.failed("a") == 1.0
    clock.advance(9.0)  # twice max_s without a failure
    assert lockout.retry_after_s("a") == 0.0
    assert lockout.failures("a") == 0


# --- through the app ---------------------------------------------------------------------


@pytest.fixture
async def limited() -> AsyncIterator[Api]:
    overrides: dict[str, Any] = {
        "connect": ["udpin:127.0.0.1:0"],
        "control_rate_per_s": 2.0,
        "control_burst": 3,
        "lockout_free_failures": 3,
        "lockout_base_s": 1.0,
        "lockout_max_s": 60.0,
        "web_dir": WEB_DIR,
    }
    async with api_for(None, **overrides) as api:
        yield api


def clocked(api: Api) -> FakeClock:
    """Give the app's limits a virtual clock."""
    clock = FakeClock()
    guards = api.app.state.api.guards
    guards.control = RateLimiter(guards.control.rate_per_s, guards.control.burst, clock)
    lockout = guards.lockout
    guards.lockout = Lockout(lockout.free_failures, lockout.base_s, lockout.max_s, clock)
    return clock


def client_at(api: Api, host: str, token: str | None = None) -> httpx.AsyncClient:
    return httpx.AsyncClient(
        transport=httpx.ASGITransport(app=api.app, client=(host, 40000)),
        base_url="http://testserver",
        headers=auth(token) if token else {},
    )


async def test_control_calls_past_the_burst_get_429_with_retry_after(limited: Api) -> None:
    clock = clocked(limited)
    client = limited.client
    # no vehicle 1: each call is answered 404, but counted first
    codes = [(await client.post("/api/v1/vehicles/1/control", json={})).status_code
             for _ in range(3)]
    assert codes == [404, 404, 404]
    refused = await client.post("/api/v1/vehicles/1/control", json={})
    assert refused.status_code == 429
    assert refused.headers["retry-after"] == "1"
    detail = refused.json()["detail"]
    assert detail["retry_after_s"] == pytest.approx(0.5)
    assert "rate limit" in detail["reason"]
    # reads are not limited
    assert (await client.get("/api/v1/vehicles")).status_code == 200
    # the observer token has its own bucket: its control call is refused by role, not rate
    observer = await client.post("/api/v1/vehicles/1/arm", json={}, headers=auth(OBSERVER))
    assert observer.status_code == 403
    clock.advance(0.5)
    assert (await client.put("/api/v1/vehicles/1/setpoint", json={})).status_code == 404
    assert (await client.put("/api/v1/vehicles/1/setpoint", json={})).status_code == 429


async def test_default_limits_let_a_pilot_stream_setpoints_at_50_hz() -> None:
    async with api_for(None, connect=["udpin:127.0.0.1:0"]) as api:
        clock = clocked(api)
        for _ in range(500):  # ten seconds of a slider at 50 Hz
            response = await api.client.put("/api/v1/vehicles/1/setpoint", json={})
            assert response.status_code == 404, response.text
            clock.advance(0.02)


async def test_wrong_tokens_lock_the_address_out_exponentially_then_recover(
    limited: Api,
) -> None:
    clock = clocked(limited)
    async with (
        client_at(limited, "10.0.0.9", "wrong-token-guess") as guesser,
        client_at(limited, "10.0.0.9", PILOT) as same_address,
        client_at(limited, "10.0.0.7", PILOT) as elsewhere,
    ):
        for _ in range(3):  # free failures
            assert (await guesser.get("/api/v1/vehicles")).status_code == 401
        assert (await guesser.get("/api/v1/vehicles")).status_code == 401  # starts a 1 s lock
        waits = []
        for _ in range(3):
            locked = await guesser.get("/api/v1/vehicles")
            assert locked.status_code == 429
            waits.append(locked.headers["retry-after"])
            # while locked no token is even checked, the right one included
            assert (await same_address.get("/api/v1/vehicles")).status_code == 429
            # a good token from another address is not locked out
            assert (await elsewhere.get("/api/v1/vehicles")).status_code == 200
            clock.advance(float(waits[-1]))
            assert (await guesser.get("/api/v1/vehicles")).status_code == 401  # doubles
        assert waits == ["1", "2", "4"]
        assert "wrong tokens" in locked.json()["detail"]["reason"]
        clock.advance(8.0)
        # recovered: the right token passes and clears the record
        assert (await same_address.get("/api/v1/vehicles")).status_code == 200
        assert limited.app.state.api.guards.lockout.failures("10.0.0.9") == 0


async def test_lockout_covers_query_tokens_and_the_scene_but_not_the_static_page(
    limited: Api,
) -> None:
    clocked(limited)
    async with client_at(limited, "10.0.0.5") as anonymous:
        for _ in range(4):
            response = await anonymous.get("/api/v1/vehicles", params={"token": "not-the-token"})
            assert response.status_code == 401
        assert (await anonymous.get("/scene/", params={"token": PILOT})).status_code == 429
        # requests without a token are not refused by the lockout: the API still says 401
        assert (await anonymous.get("/api/v1/vehicles")).status_code == 401
        # the static page reads no token: it loads, and a stale cookie there is no guess
        for _ in range(5):
            page = await anonymous.get("/index.html", headers={"Cookie": "skyhelm_token=stale"})
            assert page.status_code == 200
        assert limited.app.state.api.guards.lockout.failures("10.0.0.5") == 4


def test_secrets_are_compared_in_constant_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """Both tokens are always compared with hmac.compare_digest, whichever matches, and lease
    ids go through the same comparison (any string: no TypeError on non-ASCII)."""
    from server.control import auth
    from server.control.auth import TokenChecker, same_secret
    from server.control.lease import LeaseInvalid, LeaseManager

    calls: list[tuple[bytes, bytes]] = []
    real = auth.hmac.compare_digest

    def spy(a: bytes, b: bytes) -> bool:
        calls.append((a, b))
        return real(a, b)

    monkeypatch.setattr(auth.hmac, "compare_digest", spy)
    checker = TokenChecker(PILOT, OBSERVER)
    for token, role in ((PILOT, "pilot"), (OBSERVER, "observer"), ("pilot-token-for-test", None)):
        calls.clear()
        found = checker.role_of(token)
        assert (found.value if found else None) == role
        assert [b for _, b in calls] == [PILOT.encode(), OBSERVER.encode()]
    assert same_secret("é-lease", "é-lease")
    assert not same_secret("\udcff", "x")
    leases = LeaseManager(ttl_s=10.0)
    lease = leases.acquire(1, "pilot · t", session="rest")
    calls.clear()
    assert leases.renew(1, lease.lease_id) is lease
    assert calls == [(lease.lease_id.encode(), lease.lease_id.encode())]
    with pytest.raises(LeaseInvalid):
        leases.renew(1, "ünïcode-lease-id")
