"""The client's methods follow from the wire's call table: every call is a method of both
clients, the ones not written by hand are generated (python -m tools.gen_client) and fail
here when stale, each answers the table's model, validated, against a live server."""

from __future__ import annotations

import asyncio
from typing import Any, get_args, get_origin, get_type_hints

import pytest
from pydantic import ValidationError

from skyhelm_client import AsyncSkyHelm, CommandResult, SkyHelm
from skyhelm_client.calls import Call, Calls
from skyhelm_client.models import Answer
from skyhelm_wire.calls import CALLS
from skyhelm_wire.commands import CommandResultOut
from tests.client.conftest import pilot_url
from tests.serve_process import Served
from tools import gen_client


def _method(name: str) -> str:
    return Calls.METHOD_NAMES.get(name, name)


def test_the_checked_in_client_methods_are_current() -> None:
    assert gen_client.OUT.read_text() == gen_client.generate(), (
        "skyhelm_client/generated.py is not current: run python -m tools.gen_client"
    )


def test_the_generator_reads_the_hand_written_calls_of_the_client() -> None:
    assert gen_client.hand_written() == (Calls.BY_HAND, Calls.METHOD_NAMES)
    assert {call.name for call in CALLS} >= Calls.BY_HAND


def _answer_model(annotation: Any) -> Any:
    """The table's answer a method's annotation stands for: Answer[M] is M, list[Answer[M]]
    list[M], CommandResult CommandResultOut, None None (204)."""
    if annotation is CommandResult:
        return CommandResultOut
    if annotation in (None, type(None)):
        return None
    if annotation is bytes:
        return bytes
    if get_origin(annotation) is list:
        return list[_answer_model(get_args(annotation)[0])]  # type: ignore[misc]
    if annotation is Any:  # JSON the table gives no model for, as it is
        return Any
    assert get_origin(annotation) is Answer, annotation
    return get_args(annotation)[0]


@pytest.mark.parametrize("client", [SkyHelm, AsyncSkyHelm])
def test_every_call_is_a_method_answering_the_tables_model(client: type[Any]) -> None:
    for call in CALLS:
        method = getattr(client, _method(call.name), None)
        assert callable(method), f"{client.__name__} has no method for {call.name}"
        if call.name in Calls.BY_HAND:
            continue
        answer = get_type_hints(method)["return"]
        if client is AsyncSkyHelm:  # Coroutine[Any, Any, answer]
            answer = get_args(answer)[2]
        if _answer_model(answer) is Any:
            assert get_origin(call.answer) is dict, call.name
            continue
        assert _answer_model(answer) == call.answer, (call.name, answer)


def test_the_table_made_calls_answer_validated_models(served: Served) -> None:
    with SkyHelm(pilot_url(served)) as sky:
        assert sky.health().model.status == "ok"
        assert [vehicle.model.id for vehicle in sky.vehicles()] == [1]
        assert sky.page_config().model.fleet is False
        assert sky.signing_status().model.key_file_set is False
        assert sky.stream_stats().model.active is False
        assert sky.sticks().model.active is False
        assert sky.control_status().model.holder is None
        sky.acquire()
        assert sky.fly_sticks(throttle=0.5).model.active is True
        assert sky.stop_sticks().model.active is False
        assert "MIS_TAKEOFF_ALT" in sky.param_metadata().model.parameters
        entries = sky.audit(vehicle=1, limit=5)
        assert entries
        assert all(entry.model.vehicle == 1 for entry in entries)
        assert entries[-1].model.kind == "control"
        assert [entry.model for entry in sky.audit(limit=5)] == [e.model for e in entries]
    # a client of another vehicle reads that vehicle's audit (none here), unless it asks for all
    with SkyHelm(pilot_url(served), vehicle=2) as other:
        assert other.audit() == []
        everyone = other.audit(all_vehicles=True, limit=5)
        assert everyone
        assert all(entry.model.vehicle == 1 for entry in everyone)
        assert everyone[-1].model.data["action"] == "released"  # the first client's lease
        assert other.audit(vehicle=1, limit=5) == everyone

    async def read() -> None:
        async with AsyncSkyHelm(pilot_url(served)) as sky:
            assert (await sky.health()).model.version
            assert (await sky.sticks()).model.rate_hz > 0
            assert [entry.model.kind for entry in await sky.audit(limit=1)]

    asyncio.run(read())


def test_audit_reads_the_clients_own_vehicle_unless_asked_for_all(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    sent: list[Call] = []
    monkeypatch.setattr(SkyHelm, "_send", lambda self, call: (sent.append(call), (200, []))[1])
    with SkyHelm("http://127.0.0.1:9/?token=t", vehicle=3) as sky:  # nothing is sent
        sky.audit()
        sky.audit(limit=7, all_vehicles=True)
        sky.audit(vehicle=4)
        with pytest.raises(ValueError, match="not both"):
            sky.audit(vehicle=4, all_vehicles=True)
    assert [(call.path, call.params) for call in sent] == [
        ("/control/audit", {"vehicle": "3", "limit": "100"}),
        ("/control/audit", {"limit": "7"}),
        ("/control/audit", {"vehicle": "4", "limit": "100"}),
    ]


def test_a_picked_answer_is_validated_whole_with_the_tables_model() -> None:
    with SkyHelm("http://127.0.0.1:9/?token=t") as sky:  # nothing is sent
        call = sky._named("param", path={"name": "MIS_TAKEOFF_ALT"}, pick="value")
        assert call.path == "/vehicles/1/params/MIS_TAKEOFF_ALT"
        assert sky._answer(call, 200, {"name": "MIS_TAKEOFF_ALT", "value": 2.5}) == 2.5
        with pytest.raises(ValidationError, match="name"):  # the server dropped a field
            sky._answer(call, 200, {"value": 2.5})
        with pytest.raises(ValidationError):
            sky._answer(sky._named("params", pick="params"), 200, {"params": {"A": "x"}})
