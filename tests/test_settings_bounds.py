"""Every numeric setting is checked at startup against the bounds the code that uses it
accepts: a value outside them, NaN or infinity, from a flag or from the environment, stops
`skyhelm serve` with exit code 2 and a message naming the setting, before anything runs."""

from __future__ import annotations

import argparse
import math
import typing
from typing import Any

import annotated_types
import pytest

from server.cli import build_parser, main
from server.link.stream.streamer import MAX_RATE_HZ, MIN_RATE_HZ, SetpointStreamer
from server.settings import Settings, load_settings


def _numeric_type(annotation: Any) -> type | None:
    members = typing.get_args(annotation) or (annotation,)
    numeric = [m for m in members if m in (int, float)]
    return numeric[0] if numeric else None


def _outside(kind: type, metadata: list[Any]) -> list[str]:
    """Values just outside each bound, and for floats NaN and both infinities."""
    step = 1 if kind is int else 0.01
    values: list[str] = []
    for bound in metadata:
        if isinstance(bound, annotated_types.Ge):
            values.append(str(bound.ge - step))
        elif isinstance(bound, annotated_types.Gt):
            values.append(str(bound.gt))
        elif isinstance(bound, annotated_types.Le):
            values.append(str(bound.le + step))
        elif isinstance(bound, annotated_types.Lt):
            values.append(str(bound.lt))
    if kind is float:
        values += ["nan", "inf", "-inf"]
    return values


def _cases() -> list[tuple[str, str]]:
    cases = []
    for name, field in Settings.model_fields.items():
        kind = _numeric_type(field.annotation)
        if kind is not None:
            cases += [(name, value) for value in _outside(kind, field.metadata)]
    return cases


CASES = _cases()


def _serve_flags() -> set[str]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return set(sub.choices["serve"]._option_string_actions)


def test_every_numeric_setting_has_cases() -> None:
    names = {name for name, _ in CASES}
    assert {"port", "rate_hz", "sim_count", "sim_speed", "heartbeat_timeout_s"} <= names
    assert ("rate_hz", str(MAX_RATE_HZ + 0.01)) in CASES


@pytest.mark.parametrize(("name", "value"), CASES)
def test_out_of_bounds_from_the_environment_exits_2_naming_the_setting(
    name: str, value: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv(f"SKYHELM_{name.upper()}", value)

    assert main(["serve"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("skyhelm: invalid settings: ")
    assert f"{name}: " in err


@pytest.mark.parametrize(("name", "value"), CASES)
def test_out_of_bounds_from_a_flag_exits_2_naming_the_setting(
    name: str, value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    flag = "--" + name.replace("_", "-")
    assert flag in _serve_flags()

    assert main(["serve", f"{flag}={value}"]) == 2  # "=": argparse reads -inf as a flag
    err = capsys.readouterr().err
    assert err.startswith("skyhelm: invalid settings: ")
    assert f"{name}: " in err


def test_the_rate_that_crashed_the_streamer_is_refused_at_startup(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("SKYHELM_RATE_HZ", "150")

    assert main(["serve"]) == 2
    assert "rate_hz: Input should be less than or equal to 100" in capsys.readouterr().err


@pytest.mark.parametrize("rate_hz", [MIN_RATE_HZ, MAX_RATE_HZ])
def test_every_rate_the_settings_take_the_streamer_takes(rate_hz: float) -> None:
    settings = load_settings(rate_hz=rate_hz)
    streamer = SetpointStreamer(lambda _msg: None, rate_hz=settings.rate_hz)
    assert math.isclose(streamer.rate_hz, rate_hz)
