"""Every call of the client answers a typed value: mypy --strict on a script using the
client passes, and catches a misspelt field of a command's, an intent's, a setpoint's, the
parameters', the health's, the sticks', the stream's, the control's or the audit's answer
(the answers stay indexable as JSON, as scripts used them)."""

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
    print(sky.health().model.version, sky.arm().result_code)
    print(sky.param_metadata().model.parameters["MIS_TAKEOFF_ALT"].units)
    print(sky.fly_sticks(throttle=0.5).model.rate_hz, sky.sticks().model.stream.gaps)
    print(sky.stream_stats().model.max_gap_ms, sky.control_status().model.holder)
    print([entry.model.time_unix_s for entry in sky.audit(limit=5)])
    print([vehicle.model.sysid for vehicle in sky.vehicles()])


async def fly_async(sky: AsyncSkyHelm) -> None:
    moved = await sky.offset(north_m=5.0)
    print(moved.model.command)
    print((await sky.brake()).model.intent)
    print((await sky.health()).model.read_only, (await sky.stop_sticks()).model.active)
    print((await sky.stream_stats()).model.interval_p99_ms)
'''
MISSPELT = {
    "moved.model.via": "moved.model.vai",
    "sent.model.type_mask": "sent.model.typemask",
    "(await sky.brake()).model.intent": "(await sky.brake()).model.intnet",
    "sky.health().model.version": "sky.health().model.versoin",
    "sky.arm().result_code": "sky.arm().resultcode",
    '["MIS_TAKEOFF_ALT"].units': '["MIS_TAKEOFF_ALT"].unit',
    "model.rate_hz, sky.sticks()": "model.ratehz, sky.sticks()",
    "sky.stream_stats().model.max_gap_ms": "sky.stream_stats().model.maxgap_ms",
    "sky.control_status().model.holder": "sky.control_status().model.holdr",
    "entry.model.time_unix_s": "entry.model.time_s",
    "(await sky.stop_sticks()).model.active": "(await sky.stop_sticks()).model.activ",
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
    for attribute in ("vai", "typemask", "intnet", "versoin", "resultcode", "unit", "ratehz",
                      "maxgap_ms", "holdr", "time_s", "activ"):  # fmt: skip
        assert f'has no attribute "{attribute}"' in out, out


def test_an_answer_is_its_json_and_its_model() -> None:
    body = {"intent": "brake", "via": "hold_mode", "setpoint": None, "command": None,
            "target": None, "live": False}  # fmt: skip
    answer = Answer(body, IntentOut)
    assert dict(answer) == body
    assert answer["via"] == answer.model.via == "hold_mode"
