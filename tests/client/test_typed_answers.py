"""Every call of the client answers a typed value: mypy --strict on a script using the
client passes, and catches a misspelt field of an intent's, a setpoint's or the parameters'
answer (the answers stay indexable as JSON, as scripts used them)."""

from __future__ import annotations

from pathlib import Path

from mypy import api

from skyhelm_client import Answer
from skyhelm_wire.intents import IntentOut

SCRIPT = '''
from skyhelm_client import AsyncSkyHelm, SkyHelm, VelocityNed


def fly(sky: SkyHelm) -> None:
    moved = sky.goto(47.0, 8.0, 10.0)
    print(moved.model.via, moved.model.target, moved["intent"])
    sent = sky.set_setpoint(VelocityNed(1.0, 0.0, 0.0))
    print(sent.model.type_mask, sent.model.setpoint)
    values: dict[str, float | int | None] = sky.params("MIS_TAKEOFF_ALT")
    print(values, sky.velocity(north_m_s=1.0, frame="ned").model.live)


async def fly_async(sky: AsyncSkyHelm) -> None:
    moved = await sky.offset(north_m=5.0)
    print(moved.model.command)
    print((await sky.brake()).model.intent)
'''
MISSPELT = {
    "moved.model.via": "moved.model.vai",
    "sent.model.type_mask": "sent.model.typemask",
    "(await sky.brake()).model.intent": "(await sky.brake()).model.intnet",
}


def _mypy(tmp_path: Path, text: str) -> tuple[str, int]:
    script = tmp_path / "script.py"
    script.write_text(text)
    out, err, status = api.run(["--strict", "--no-incremental", "--cache-dir", str(tmp_path / "c"),
                                str(script)])  # fmt: skip
    return out + err, status


def test_a_script_using_the_typed_answers_passes_mypy_strict(tmp_path: Path) -> None:
    out, status = _mypy(tmp_path, SCRIPT)
    assert status == 0, out


def test_mypy_strict_catches_a_misspelt_field(tmp_path: Path) -> None:
    text = SCRIPT
    for right, wrong in MISSPELT.items():
        text = text.replace(right, wrong)
    out, status = _mypy(tmp_path, text)
    assert status == 1, out
    for attribute in ("vai", "typemask", "intnet"):
        assert f'has no attribute "{attribute}"' in out, out


def test_an_answer_is_its_json_and_its_model() -> None:
    body = {"intent": "brake", "via": "hold_mode", "setpoint": None, "command": None,
            "target": None, "live": False}  # fmt: skip
    answer = Answer(body, IntentOut)
    assert dict(answer) == body
    assert answer["via"] == answer.model.via == "hold_mode"
