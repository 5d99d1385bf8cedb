"""The control model's rules on the event loop's virtual clock: TTL bounds, asking the holder
for control (grant, deny, no answer, letting go meanwhile), the control events every client
sees, session names, and the settings that bound them."""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass
from typing import Any, cast

import pytest

from server.control.auth import Role, TokenChecker
from server.control.control_events import ControlEvents
from server.control.lease import (
    Lease,
    LeaseEnd,
    LeaseInvalid,
    LeaseManager,
    TakeoverRefused,
    TtlOutOfBounds,
    UnknownRequest,
)
from server.settings import SettingsError, load_settings
from tests.waiting import wait_for


def _leases() -> LeaseManager:
    return LeaseManager(120.0, min_ttl_s=1.0, max_ttl_s=600.0)


class _EventSink:
    """A vehicle as the control events see it: it keeps what was published."""

    def __init__(self) -> None:
        self.events: list[tuple[str, dict[str, object]]] = []

    def publish_event(self, kind: str, data: dict[str, object]) -> None:
        self.events.append((kind, data))

    def get(self, vehicle_id: int) -> _EventSink | None:
        return self if vehicle_id == 1 else None

    def control(self) -> list[dict[str, object]]:
        return [data for kind, data in self.events if kind == "control"]


def _watched_leases() -> tuple[LeaseManager, _EventSink]:
    """Leases with the server's bounds, and the control events they cause."""
    leases = _leases()
    sink = _EventSink()
    ControlEvents(leases, sink)
    return leases, sink


# ---- TTL asked by the client, within the server's bounds -----------------------------------


@pytest.mark.looptime
async def test_the_client_asks_the_ttl_within_the_bounds() -> None:
    leases = _leases()
    assert leases.acquire(1, "a", session="rest").ttl_s == 120.0
    assert leases.acquire(2, "b", session="rest", ttl_s=30.0).ttl_s == 30.0
    for asked, limit in ((0.5, 1.0), (601.0, 600.0), (math.nan, 1.0)):
        with pytest.raises(TtlOutOfBounds) as refused:
            leases.acquire(3, "c", session="rest", ttl_s=asked)
        assert refused.value.limit == limit
    assert leases.current(3) is None


@pytest.mark.looptime
async def test_a_rest_script_keeps_control_through_a_60_s_wait_by_default() -> None:
    leases = _leases()
    lease = leases.acquire(1, "script", session="rest")
    await asyncio.sleep(60.0)
    assert leases.expire_due() == []
    leases.renew(1, lease.lease_id)
    await asyncio.sleep(119.9)
    assert leases.expire_due() == []
    await asyncio.sleep(0.1)
    assert leases.expire_due() == [lease]


@pytest.mark.looptime
async def test_a_renewal_may_change_the_ttl_within_the_bounds() -> None:
    leases = _leases()
    lease = leases.acquire(1, "a", session="ws")
    assert leases.renew(1, lease.lease_id, ttl_s=5.0).ttl_s == 5.0
    assert leases.status(1) == ("a", 5.0)
    with pytest.raises(TtlOutOfBounds):
        leases.renew(1, lease.lease_id, ttl_s=1000.0)
    assert lease.ttl_s == 5.0


# ---- handover -----------------------------------------------------------------------------


@dataclass
class _Asking:
    alice: Lease  # the holder, asked
    takeover: asyncio.Future[Lease]  # bob's take_over, waiting for the answer
    request_id: str


async def _bob_asks_alice(
    leases: LeaseManager, *, ask_s: float = 10.0, session: str = "ws", ttl_s: float | None = None
) -> _Asking:
    """Alice holds vehicle 1; bob asks her for it. Returns once she is being asked."""
    alice = leases.acquire(1, "pilot · alice", session="ws")
    takeover = asyncio.ensure_future(
        leases.take_over(1, "pilot · bob", session=session, ask_s=ask_s, ttl_s=ttl_s)
    )

    def request_id() -> str | None:
        return alice.request.request_id if alice.request is not None else None

    await wait_for(request_id, 5.0, "the takeover request")
    asked = request_id()
    assert asked is not None
    return _Asking(alice, takeover, asked)


@pytest.mark.looptime
async def test_a_granted_takeover_hands_the_lease_over() -> None:
    leases, events = _watched_leases()
    asking = await _bob_asks_alice(leases, session="rest", ttl_s=30.0)
    alice, request_id = asking.alice, asking.request_id
    assert leases.current(1) is alice  # the holder flies on while being asked
    loop = asyncio.get_running_loop()
    answered_at = loop.time()
    leases.answer(1, alice.lease_id, request_id, True)
    bob = await asking.takeover
    assert loop.time() == answered_at  # the answer, not the ask time, ends the wait

    assert bob.holder == "pilot · bob"
    assert bob.taken_from == "pilot · alice"
    assert bob.ttl_s == 30.0
    assert alice.end is LeaseEnd.TAKEN_OVER
    assert (alice.taken_by, alice.forced) == ("pilot · bob", False)
    assert [e["action"] for e in events.control()] == [
        "acquired",
        "takeover_requested",
        "takeover_granted",
        "taken_over",
        "acquired",
    ]
    requested = events.control()[1]
    assert requested["by"] == "pilot · bob"
    assert requested["holder"] == "pilot · alice"
    assert requested["request_id"] == request_id
    assert requested["timeout_s"] == 10.0
    taken = events.control()[3]
    assert (taken["holder"], taken["previous_holder"], taken["forced"]) == (
        "pilot · bob",
        "pilot · alice",
        False,
    )
    acquired = events.control()[4]
    assert (acquired["holder"], acquired["previous_holder"], acquired["session"]) == (
        "pilot · bob",
        "pilot · alice",
        "rest",
    )
    # the old holder's id now hears who took control
    with pytest.raises(LeaseInvalid) as stale:
        leases.renew(1, alice.lease_id)
    assert "taken over by pilot · bob" in str(stale.value)
    assert stale.value.holder == "pilot · bob"


@pytest.mark.looptime
async def test_a_denied_takeover_leaves_the_holder_in_control() -> None:
    leases, events = _watched_leases()
    asking = await _bob_asks_alice(leases)
    alice = asking.alice
    leases.answer(1, alice.lease_id, asking.request_id, False)
    answered_at = asyncio.get_running_loop().time()
    with pytest.raises(TakeoverRefused) as refused:
        await asking.takeover
    assert asyncio.get_running_loop().time() == answered_at
    assert str(refused.value) == "denied by pilot · alice"
    assert refused.value.holder == "pilot · alice"
    assert leases.current(1) is alice
    assert alice.request is None
    assert events.control()[-1]["action"] == "takeover_denied"


@pytest.mark.looptime
async def test_an_unanswered_takeover_is_refused_after_the_ask_time() -> None:
    leases, events = _watched_leases()
    alice = leases.acquire(1, "pilot · alice", session="rest")
    loop = asyncio.get_running_loop()
    start = loop.time()
    with pytest.raises(TakeoverRefused) as refused:
        await leases.take_over(1, "pilot · bob", session="rest", ask_s=10.0)
    assert loop.time() - start == pytest.approx(10.0)
    assert str(refused.value) == "pilot · alice did not answer within 10 s"
    assert leases.current(1) is alice
    assert events.control()[-1]["action"] == "takeover_timed_out"
    # too late to answer now
    with pytest.raises(UnknownRequest):
        leases.answer(1, alice.lease_id, "anything", True)


@pytest.mark.looptime
async def test_a_holder_letting_go_while_asked_lets_the_asker_in() -> None:
    leases = _leases()
    asking = await _bob_asks_alice(leases)
    leases.release(1, asking.alice.lease_id, LeaseEnd.CLOSED)
    released_at = asyncio.get_running_loop().time()
    bob = await asking.takeover
    assert asyncio.get_running_loop().time() == released_at
    assert leases.current(1) is bob
    assert bob.taken_from is None  # nobody held it any more when bob got it


@pytest.mark.looptime
async def test_forced_takeover_needs_no_answer_and_one_ask_at_a_time() -> None:
    leases, events = _watched_leases()
    asking = await _bob_asks_alice(leases)
    alice = asking.alice
    with pytest.raises(TakeoverRefused, match="pilot · bob is already asking pilot · alice"):
        await leases.take_over(1, "pilot · carol", session="rest", ask_s=10.0)
    carol = await leases.take_over(1, "pilot · carol", session="rest", ask_s=10.0, force=True)
    assert (alice.end, alice.forced, carol.taken_from) == (
        LeaseEnd.TAKEN_OVER,
        True,
        "pilot · alice",
    )
    # bob was asking alice, who no longer holds it; carol does now, so bob is refused
    with pytest.raises(TakeoverRefused):
        await asking.takeover
    assert leases.current(1) is carol
    assert [e["action"] for e in events.control()][-2:] == ["taken_over", "acquired"]


@pytest.mark.looptime
async def test_an_asker_that_goes_away_withdraws_its_request() -> None:
    leases, events = _watched_leases()
    asking = await _bob_asks_alice(leases)
    asking.takeover.cancel()
    with pytest.raises(asyncio.CancelledError):
        await asking.takeover
    assert asking.alice.request is None
    assert events.control()[-1]["action"] == "takeover_withdrawn"
    with pytest.raises(UnknownRequest):
        leases.answer(1, asking.alice.lease_id, asking.request_id, True)


@pytest.mark.looptime
async def test_only_the_holder_answers_a_takeover_request() -> None:
    leases = _leases()
    asking = await _bob_asks_alice(leases, ask_s=1.0)
    with pytest.raises(LeaseInvalid):
        leases.answer(1, "not-the-holders-lease", asking.request_id, True)
    with pytest.raises(TakeoverRefused):
        await asking.takeover


@pytest.mark.looptime
async def test_control_events_say_who_holds_it_and_for_how_long() -> None:
    leases, events = _watched_leases()
    lease = leases.acquire(1, "pilot · alice", session="rest")
    await asyncio.sleep(2.5)
    leases.rename(1, lease.lease_id, "pilot · alice's laptop")
    await asyncio.sleep(2.5)
    leases.release(1, lease.lease_id)
    acquired, renamed, released = events.control()
    assert acquired == {
        "action": "acquired",
        "session": "rest",
        "holder": "pilot · alice",
        "previous_holder": None,
        "since_s": 0.0,
        "ttl_s": 120.0,
    }
    assert renamed == {
        "action": "renamed",
        "session": "rest",
        "holder": "pilot · alice's laptop",
        "previous_holder": "pilot · alice",
        "since_s": 2.5,
    }
    assert released == {
        "action": "released",
        "session": "rest",
        "holder": None,
        "previous_holder": "pilot · alice's laptop",
        "since_s": 5.0,
    }
    # the older "lease" events are still published beside them
    assert [data["action"] for kind, data in events.events if kind == "lease"] == [
        "acquired",
        "released",
    ]


# ---- names and settings -------------------------------------------------------------------


def test_tokens_have_names_from_the_settings() -> None:
    settings = load_settings(
        token="pilot-token-1234",
        observer_token="observer-token-1234",
        token_name="ops",
        observer_token_name="wall screen",
    )
    tokens = TokenChecker.from_settings(settings)
    assert tokens.role_of("pilot-token-1234") is Role.PILOT
    assert tokens.name_of(Role.PILOT) == "ops"
    assert tokens.name_of(Role.OBSERVER) == "wall screen"
    default = TokenChecker("pilot-token-1234")
    assert default.name_of(Role.PILOT) == "pilot"


def test_session_names_are_token_name_and_client_label() -> None:
    from server.http.context import ApiContext

    tokens = TokenChecker("pilot-token-1234", pilot_name="ops")
    context = ApiContext(*cast("Any", (None, tokens, None, None, None)))
    address = cast("Any", type("Address", (), {"host": "10.0.0.2", "port": 5121})())
    assert context.holder_name("Chrome tab 7f3a", "ws", address) == "ops · Chrome tab 7f3a"
    assert context.holder_name(None, "rest", address) == "ops · rest 10.0.0.2:5121"
    assert context.holder_name("  ", "ws", None) == "ops · ws"


def test_lease_ttl_settings_are_checked_together() -> None:
    defaults = load_settings(token="pilot-token-1234")
    assert (defaults.lease_ttl_s, defaults.lease_ttl_min_s, defaults.lease_ttl_max_s) == (
        120.0,
        1.0,
        600.0,
    )
    assert (defaults.deadman_timeout_s, defaults.takeover_ask_s) == (1.0, 10.0)
    with pytest.raises(SettingsError, match=r"lease_ttl_s \(0.5\) must lie within"):
        load_settings(token="pilot-token-1234", lease_ttl_s=0.5)
    with pytest.raises(SettingsError) as refused:
        load_settings(token="pilot-token-1234", lease_ttl_s=700.0)
    assert "pilot-token-1234" not in str(refused.value)
    with pytest.raises(SettingsError, match="deadman_timeout_s"):
        load_settings(token="pilot-token-1234", deadman_timeout_s=0.1)
    manager = LeaseManager.from_settings(
        load_settings(token="pilot-token-1234", lease_ttl_s=30.0, lease_ttl_max_s=60.0)
    )
    assert (manager.ttl_s, manager.min_ttl_s, manager.max_ttl_s) == (30.0, 1.0, 60.0)
