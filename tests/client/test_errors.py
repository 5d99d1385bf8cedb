"""Each error answer the API gives becomes its typed exception with what it named."""

from __future__ import annotations

import pytest

from skyhelm_client import InvalidInput, NoAnswer, NoLease, Refused, SkyHelm, SkyHelmError
from skyhelm_client.errors import error_for


def test_a_refused_command_carries_its_mav_result_and_reason() -> None:
    body = {
        "command": "MAV_CMD_COMPONENT_ARM_DISARM",
        "result": "DENIED",
        "result_code": 2,
        "elapsed_ms": 3.0,
        "reason": "Disarming denied: not landed",
    }
    error = error_for(409, body)
    assert isinstance(error, Refused)
    assert (error.status, error.result, error.result_code) == (409, "DENIED", 2)
    assert error.reason == "Disarming denied: not landed"
    assert str(error) == "409: Disarming denied: not landed"
    timeout = error_for(504, {**body, "result": "TIMEOUT", "result_code": None, "reason": None})
    assert isinstance(timeout, NoAnswer)
    assert timeout.reason == "TIMEOUT"


def test_details_and_pydantic_errors_name_the_field() -> None:
    envelope = error_for(
        422, {"detail": {"reason": "outside the envelope", "field": "north_m", "limit": 500.0}}
    )
    assert isinstance(envelope, InvalidInput)
    assert (envelope.field, envelope.limit) == ("north_m", 500.0)
    held = error_for(423, {"detail": {"reason": "taken over by pilot · bob", "holder": "b"}})
    assert isinstance(held, NoLease)
    assert held.holder == "b"
    listed = error_for(
        422,
        {"detail": [{"loc": ["body", "position_ned", "north_m"], "msg": "not a number"}]},
    )
    assert listed.field == "position_ned.north_m"
    assert listed.reason == "not a number"
    assert type(error_for(418, "teapot")) is SkyHelmError


def test_an_unreachable_server_is_a_skyhelm_error_with_status_0() -> None:
    with SkyHelm("http://127.0.0.1:9", token="any-token") as sky, pytest.raises(SkyHelmError) as e:
        sky.health()
    assert e.value.status == 0


def test_the_url_must_carry_a_token() -> None:
    with pytest.raises(ValueError, match="token"):
        SkyHelm("http://127.0.0.1:8000/")
