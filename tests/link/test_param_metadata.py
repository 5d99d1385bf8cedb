"""What a parameter is, read from PX4's parameters.json, and the range a value is held to."""

from __future__ import annotations

from typing import Any

import pytest

from server.link.plugins.component_metadata import MetadataError
from server.link.plugins.param_metadata import ParamMetadata, parse_parameters

# the shape PX4 v1.16 generates (build/px4_sitl_default/parameters.json)
DOCUMENT: dict[str, Any] = {
    "version": 1,
    "parameters": [
        {"category": "Standard", "decimalPlaces": 1, "default": 12.0,
         "group": "Multicopter Position Control", "increment": 1.0,
         "longDesc": "Absolute maximum for all velocity controlled modes.",
         "max": 20.0, "min": 0.0, "name": "MPC_XY_VEL_MAX",
         "shortDesc": "Maximum horizontal velocity", "type": "Float", "units": "m/s"},
        {"default": 0, "group": "Commander", "name": "NAV_DLL_ACT", "type": "Int32", "min": 0,
         "shortDesc": "Set GCS connection loss failsafe mode",
         "values": [{"description": "Disabled", "value": 0},
                    {"description": "Hold mode", "value": 1}]},
        {"default": 0, "group": "System", "name": "SYS_HITL", "rebootRequired": True,
         "type": "Int32", "bitmask": [{"index": 0, "description": "first"}]},
        {"shortDesc": "no name: skipped"},
    ],
}  # fmt: skip


def test_each_parameter_is_described_with_units_range_default_and_choices() -> None:
    described = parse_parameters(DOCUMENT)
    assert set(described) == {"MPC_XY_VEL_MAX", "NAV_DLL_ACT", "SYS_HITL"}
    velocity = described["MPC_XY_VEL_MAX"]
    assert (velocity.min, velocity.max, velocity.units) == (0.0, 20.0, "m/s")
    assert velocity.default == 12.0
    assert velocity.range_text() == "0 … 20 m/s"
    assert described["NAV_DLL_ACT"].values[1].description == "Hold mode"
    assert described["NAV_DLL_ACT"].range_text() == "≥ 0"
    assert described["SYS_HITL"].reboot_required
    assert described["SYS_HITL"].bitmask[0].value == 0
    assert described["SYS_HITL"].range_text() == ""


def test_a_value_outside_the_range_is_refused_in_the_metadata_words() -> None:
    velocity = parse_parameters(DOCUMENT)["MPC_XY_VEL_MAX"]
    assert velocity.out_of_range(20.0) is None
    assert velocity.out_of_range(0) is None
    assert velocity.out_of_range(1000) == (
        "MPC_XY_VEL_MAX: 1000 is outside 0 … 20 m/s (Maximum horizontal velocity)"
    )
    assert velocity.out_of_range(-0.5) is not None
    assert velocity.out_of_range(float("nan")) is not None
    assert parse_parameters(DOCUMENT)["SYS_HITL"].out_of_range(-7) is None  # no range given


class _Source:
    def __init__(self, answer: dict[str, Any] | MetadataError) -> None:
        self.answer = answer
        self.calls = 0

    async def parameters(self) -> dict[str, Any]:
        self.calls += 1
        if isinstance(self.answer, MetadataError):
            raise self.answer
        return self.answer


async def test_the_metadata_is_read_once_and_a_failure_is_remembered_for_a_while() -> None:
    now = [0.0]
    source = _Source(MetadataError("the vehicle offers no component metadata"))
    metadata = ParamMetadata(source, lambda: now[0])  # type: ignore[arg-type]
    for _ in range(2):
        with pytest.raises(MetadataError, match="offers no component metadata"):
            await metadata.get()
    assert source.calls == 1  # the second caller got the remembered error at once
    now[0] = metadata.retry_s + 1
    source.answer = DOCUMENT
    assert "MPC_XY_VEL_MAX" in await metadata.get()
    await metadata.get()
    assert source.calls == 2
    metadata.forget()  # a reboot
    await metadata.get()
    assert source.calls == 3
