"""The Foxglove layout in docs/foxglove-layout.json, built with the SDK's layout types so
it stays a layout Foxglove reads: the map (position), the 3D view (pose, following the
vehicle), attitude and altitude plots, the log, and the raw state.

    python -m server.foxglove.layout > docs/foxglove-layout.json
"""

from __future__ import annotations

import json

import foxglove.layouts as fl

from server.foxglove.channels import WORLD_FRAME, vehicle_frame, vehicle_prefix


def layout(sysid: int = 1) -> fl.Layout:
    prefix = vehicle_prefix(sysid)
    state = f"{prefix}/state"
    attitude = fl.PlotPanel(title="attitude (deg)", config=fl.PlotConfig(paths=[
        fl.PlotSeries(value=f"{state}.attitude.{axis}_deg", label=axis)
        for axis in ("roll", "pitch", "yaw")
    ]))
    altitude = fl.PlotPanel(title="altitude (m)", config=fl.PlotConfig(paths=[
        fl.PlotSeries(value=f"{state}.global.alt_rel_m", label="above home (state)"),
        fl.PlotSeries(value=f"{prefix}/mavlink/ALTITUDE.altitude_relative",
                      label="ALTITUDE.altitude_relative"),
    ]))
    scene = fl.ThreeDeePanel(title="3D", config=fl.ThreeDeeConfig(
        follow_tf=vehicle_frame(sysid), fixed_frame=WORLD_FRAME,
        layers={"grid": fl.BaseRendererGridLayerSettings()},
        topics={f"{prefix}/pose": fl.BaseRendererPoseTopicSettings(visible=True)},
    ))
    map_panel = fl.MapPanel(title="map", config=fl.MapConfig(follow_topic=f"{prefix}/location"))
    log = fl.LogPanel(title="log", config=fl.LogConfig(topic_to_render=f"{prefix}/log"))
    raw = fl.RawMessagesPanel(title="state", config=fl.RawMessagesConfig(topic_path=state))
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=1, content=fl.SplitContainer(direction="column", items=[
            fl.SplitItem(content=map_panel), fl.SplitItem(content=scene),
        ])),
        fl.SplitItem(proportion=1, content=fl.SplitContainer(direction="column", items=[
            fl.SplitItem(content=attitude), fl.SplitItem(content=altitude),
            fl.SplitItem(content=log),
        ])),
        fl.SplitItem(proportion=0.6, content=raw),
    ]))


def layout_json(sysid: int = 1) -> str:
    return json.dumps(json.loads(layout(sysid).to_json()), indent=2) + "\n"


if __name__ == "__main__":
    print(layout_json(), end="")
