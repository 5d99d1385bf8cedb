"""The client's hand-written methods (``Calls.BY_HAND``, calls.py) answer what the wire's
table says their call answers: each method's declared answer is the one of the sender it
sends with, the clients' type arguments (generated.py) make that sender's answer a type
carrying the call's answer model (``Answer[IntentOut]`` for ``IntentOut``, ``CommandResult``
for ``CommandResultOut``, the picked field's type for a picked answer), and sync.py and
aio.py declare the same. A row whose answer changes, or a method sending with the wrong
sender, fails here. Nothing is sent: the senders record the call."""

from __future__ import annotations

import inspect
import types
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar, Union, get_args, get_origin, get_type_hints

import pytest
from pydantic import BaseModel

from skyhelm_client import AsyncSkyHelm, CommandResult, PositionNed, SkyHelm, State
from skyhelm_client.calls import Call, Calls
from skyhelm_client.generated import AsyncCalls, SyncCalls
from skyhelm_client.models import Answer
from skyhelm_wire.calls import CALL
from skyhelm_wire.control import AuditEntryOut, LeaseOut
from skyhelm_wire.intents import IntentOut

# the arguments a hand-written method cannot do without
ARGUMENTS: dict[str, tuple[Any, ...]] = {
    "set_mode": ("HOLD",),
    "reposition": (47.0, 8.0),
    "vtol_transition": ("fixed_wing",),
    "set_setpoint": (PositionNed(north_m=0, east_m=0, down_m=-5),),
    "goto": (47.0, 8.0),
    "param": ("MIS_TAKEOFF_ALT",),
    "set_param": ("MIS_TAKEOFF_ALT", 2.5),
}
KEYWORDS: dict[str, dict[str, Any]] = {
    "set_origin": {"lat_deg": 47.0, "lon_deg": 8.0, "alt_amsl_m": 400.0},
}


def _senders() -> dict[str, TypeVar]:
    """Each sender of ``Calls`` (``_intent``, ...) and the type parameter it answers."""
    found = {}
    for name, hint in get_type_hints(Calls).items():
        if get_origin(hint) is Callable and get_args(hint)[0] == [Call]:
            answer = get_args(hint)[1]
            if isinstance(answer, TypeVar):
                found[name] = answer
    return found


SENDERS = _senders()


def _type_arguments(client: type[Any]) -> dict[TypeVar, Any]:
    """What each type parameter of ``Calls`` is for ``client`` (SyncCalls, AsyncCalls)."""
    base = next(base for base in client.__orig_bases__ if get_origin(base) is Calls)
    return dict(zip(Calls.__parameters__, get_args(base), strict=True))


def _hand_written_methods() -> list[str]:
    return [
        name
        for name, value in vars(Calls).items()
        if inspect.isfunction(value) and not name.startswith("_") and name != "wait_until"
    ]


def _sent(method: str) -> tuple[str, str, str | None]:
    """What calling ``method`` sends: the table's call by name, the sender, the picked key."""
    sky = SkyHelm("http://127.0.0.1:9/?token=t")  # nothing is sent
    names: list[str] = []
    sent: list[tuple[str, Call]] = []
    named = sky._named
    sky._named = lambda name, *a, **k: (names.append(name), named(name, *a, **k))[1]  # type: ignore[method-assign]
    for sender in SENDERS:
        setattr(sky, sender, lambda call, sender=sender: sent.append((sender, call)))
    getattr(sky, method)(*ARGUMENTS.get(method, ()), **KEYWORDS.get(method, {}))
    sky.close()
    assert len(sent) == 1, (method, sent)
    assert len(names) == 1, (method, names)
    return names[0], sent[0][0], sent[0][1].pick


def _members(kind: Any) -> set[Any]:
    """A union's members (int is a float too, as for mypy)."""
    members = set(get_args(kind)) if get_origin(kind) in (Union, types.UnionType) else {kind}
    return {float if member is int else member for member in members}


def _carries(answer: Any, model: Any) -> bool:
    """``answer``, a client's answer type, carries the table's ``model``."""
    if model is None:
        return answer is type(None)
    if get_origin(answer) is Answer:
        return bool(get_args(answer)[0] is model)
    if get_origin(answer) is list or get_origin(model) is list:
        return get_origin(answer) is get_origin(model) and _carries(
            get_args(answer)[0], get_args(model)[0]
        )
    if isinstance(answer, type) and issubclass(answer, BaseModel):  # CommandResult, Lease
        return issubclass(answer, model)
    if isinstance(answer, type) and "model" in get_type_hints(answer):  # State
        return bool(get_type_hints(answer)["model"] is model)
    return _members(answer) >= _members(model) and get_origin(answer) == get_origin(model)


def test_every_hand_written_call_has_a_method_here() -> None:
    methods = _hand_written_methods()
    assert {_sent(method)[0] for method in methods} == Calls.BY_HAND
    assert "take_over" in methods  # a second method of the "acquire" call


@pytest.mark.parametrize("method", _hand_written_methods())
@pytest.mark.parametrize(
    ("generated", "client"),
    [(SyncCalls, SkyHelm), (AsyncCalls, AsyncSkyHelm)],
    ids=["sync", "async"],
)
def test_a_hand_written_method_answers_the_tables_model(
    method: str, generated: type[Any], client: type[Any]
) -> None:
    name, sender, pick = _sent(method)
    declared = get_type_hints(getattr(Calls, method))["return"]
    assert declared is SENDERS[sender], f"{method} declares {declared}, sends with {sender}"
    answer = _type_arguments(generated)[declared]
    if generated is AsyncCalls:
        assert get_origin(answer) is Coroutine
        answer = get_args(answer)[2]
    if answer is None:
        answer = type(None)
    # what the client's own sender declares (an async one: what it is awaited for)
    assert get_type_hints(getattr(client, sender))["return"] == answer, (client, sender)
    model = CALL[name].answer
    if pick is not None:
        model = model.model_fields[pick].annotation
    assert _carries(answer, model), f"{method}: {answer} for the table's {model} ({name})"


def test_a_mismatch_fails() -> None:
    assert not _carries(Answer[IntentOut], LeaseOut)
    assert not _carries(CommandResult, IntentOut)
    assert not _carries(State, IntentOut)
    assert not _carries(list[Answer[IntentOut]], list[AuditEntryOut])
    assert not _carries(float, float | int | None)  # a parameter's value may be null
    assert _carries(float | None, float | int | None)


def test_a_parameter_whose_value_is_not_finite_reads_none(monkeypatch: pytest.MonkeyPatch) -> None:
    """The table's ``ParamOut.value`` may be null (not a finite number): the client's
    ``param`` answers None for it (a float otherwise), as its declared answer says."""
    answers = iter([None, 3])
    monkeypatch.setattr(SkyHelm, "_send", lambda self, call: (200, next(answers)))
    with SkyHelm("http://127.0.0.1:9/?token=t") as sky:  # nothing is sent
        assert sky.param("MIS_TAKEOFF_ALT") is None
        value = sky.param("MIS_TAKEOFF_ALT")
    assert isinstance(value, float)
    assert value == 3.0
