"""A click in the scene reaches the telemetry socket as the wire's scene_click message."""

from __future__ import annotations

import dataclasses

from server.scene.hub import ClickPoint
from skyhelm_wire.messages import SceneClickMessage


def test_a_click_point_is_the_wire_scene_click_message() -> None:
    click = ClickPoint(3, 12.5, 1.0, 2.0, 0.0, 47.0, 8.0, 400.0)
    message = {"type": "scene_click", **dataclasses.asdict(click)}
    assert SceneClickMessage.model_validate(message).model_dump() == message
    assert set(SceneClickMessage.model_fields) == {"type", *dataclasses.asdict(click)}
