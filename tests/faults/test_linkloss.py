"""A 5 s partition while the vehicle flies OFFBOARD, the simulated PX4 behind the fault proxy
and the whole app in front (REST and the telemetry WebSocket over a real uvicorn).

What must hold: the vehicle's own offboard-loss failsafe fires after COM_OF_LOSS_T; SkyHelm
shows the loss within about a second on REST and the WebSocket (state and event) and stops
streaming; on the heal it does not resume by itself (PX4 would re-enter OFFBOARD the moment
setpoints came back), its first state does not show the mode from before the cut, the state
is fresh within 1 s, and an event tells what the vehicle did meanwhile. The lease stays.
"""

from __future__ import annotations

import time
from typing import Any

from tests.api.conftest import OBSERVER, Api, api_for
from tests.faults.linkloss_rig import Rig, WsLog, proxied_sim, rest_state, ws_logging
from tests.serving import uvicorn_serving
from tests.waiting import eventually, holds_for, wait_for

PARTITION_S = 5.0
CLIMB_TO = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -6.0}
LIVE_FIELDS = {"mode", "armed", "position_ned", "global_position", "attitude"}


async def _fly_offboard(api: Api) -> None:
    await api.take_control()
    arm = await api.control("arm")
    assert arm.status_code == 200, arm.text
    start = await api.control("offboard/start", {"setpoint": CLIMB_TO})
    assert start.status_code == 200, start.text
    await api.wait_state(lambda s: s["position_ned"]["down_m"] < -5.0, 20.0, "climb to 5 m")


async def test_partition_in_offboard_stops_the_stream_and_reports_on_heal() -> None:
    async with proxied_sim() as rig, api_for(None, connect=[rig.url]) as api:
        await wait_for(lambda: api.app.state.api.registry.get(1) is not None, 10.0, "discovery")
        await api.wait_ready()
        async with uvicorn_serving(api.app) as host:
            url = f"ws://{host}/api/v1/ws/telemetry?token={OBSERVER}&vehicle=1&rate_hz=20"
            async with ws_logging(url) as log:
                await _partition_scenario(rig, api, log)


async def _partition_scenario(rig: Rig, api: Api, log: WsLog) -> None:
    await _fly_offboard(api)
    before = await api.state()
    assert before["mode"] == "OFFBOARD"
    assert before["stream"]["active"]
    holder = before["lease"]["holder"]
    server_vehicle = api.vehicle()
    sim = rig.vehicle

    cut = time.monotonic()
    rig.proxy.partition(PARTITION_S)

    # the vehicle: PX4's offboard-loss failsafe after COM_OF_LOSS_T without setpoints
    await wait_for(lambda: sim.mode_name != "OFFBOARD", 5.0, "the sim's offboard failsafe")
    failsafe_after_s = sim.now_s - sim.commander.offboard.received_s
    of_loss_t = sim.params.get("COM_OF_LOSS_T")
    assert of_loss_t <= failsafe_after_s < of_loss_t + 0.6
    assert sim.commander.user_mode.name == "OFFBOARD"  # as PX4: the user's mode stays

    # SkyHelm: lost at once on REST, stream stopped, every live field marked stale
    lost = await api.wait_state(lambda s: not s["connected"], 5.0, "REST shows the loss",
                                renew=False)
    detect_s = time.monotonic() - cut
    assert detect_s < 2.5  # a 1 s silence bound, checked every 0.1 s
    assert lost["stream"]["active"] is False
    assert set(lost["stale"]) >= LIVE_FIELDS
    assert lost["lost_reason"] == "nothing heard for 1.0 s"  # how it was noticed
    # ... and on the WebSocket: the event and a state saying so
    await wait_for(lambda: any(not e["connected"] for e in log.events("connection")), 5.0,
                   "WS connection event")
    await wait_for(lambda: any(not m["connected"] for _, m in log.states()), 5.0, "WS state")
    assert {m["lost_reason"] for _, m in log.states() if not m["connected"]} == {
        "nothing heard for 1.0 s"}
    stopped = [e for e in log.events("stream") if e.get("reason") == "link lost"]
    assert stopped, log.events("stream")
    sent_at_loss = server_vehicle.stream_stats().sent
    await holds_for(lambda: server_vehicle.stream_stats().sent == sent_at_loss, 1.0,
                    "nothing streamed while the vehicle is lost")

    # the heal: back, and the first states must not show OFFBOARD (the mode before the cut)
    heal_seen: list[dict[str, Any]] = []

    async def back() -> dict[str, Any] | None:
        state = await rest_state(api.client)
        if state["connected"]:
            heal_seen.append(state)
        return state if state["connected"] else None

    first_back = await eventually(back, PARTITION_S + 5.0, "the link back", poll_s=0.01)
    back_at = time.monotonic()
    recover_s = back_at - cut - PARTITION_S
    assert first_back["mode"] != "OFFBOARD", first_back["mode"]
    assert first_back["lost_reason"] is None

    async def fresh() -> dict[str, Any] | None:
        state = await rest_state(api.client)
        heal_seen.append(state)
        return state if not (LIVE_FIELDS & set(state["stale"])) else None

    fresh_state = await eventually(fresh, 3.0, "fresh state", poll_s=0.01)
    fresh_s = time.monotonic() - back_at
    assert fresh_s < 1.0
    assert all(s["mode"] != "OFFBOARD" for s in heal_seen), [s["mode"] for s in heal_seen]
    assert fresh_state["mode"] == sim.mode_name == "POSCTL"  # COM_OBL_RC_ACT 0: Position
    assert fresh_state["user_mode"] == "OFFBOARD"

    # the operator is told what happened, and the stream stays stopped (PX4 would re-enter
    # OFFBOARD on the first setpoint)
    await wait_for(lambda: log.events("link_restored"), 5.0, "link_restored event")
    report = log.events("link_restored")[0]
    assert report["mode_before"] == "OFFBOARD"
    assert report["mode_after"] == "POSCTL"
    assert report["failsafe"] is True
    assert "vehicle left OFFBOARD for POSCTL (failsafe)" in report["text"]
    assert "altitude" in report["text"]
    assert any("link back" in e.get("reason", "") for e in log.events("stream"))
    received_s = sim.commander.offboard.received_s
    await holds_for(
        lambda: sim.mode_name != "OFFBOARD" and sim.commander.offboard.received_s == received_s
        and not server_vehicle.streamer_active,
        1.5, "no setpoint after the heal until the operator sends one",
    )
    state = await api.state()
    assert state["stream"]["active"] is False
    assert state["lease"]["holder"] == holder

    # the operator asks: the stream resumes and PX4 returns to OFFBOARD by itself
    again = await api.control("setpoint", CLIMB_TO)
    assert again.status_code == 200, again.text
    await wait_for(lambda: sim.mode_name == "OFFBOARD", 5.0, "OFFBOARD again on a setpoint")

    print(
        f"\npartition {PARTITION_S:.1f} s in OFFBOARD (sim): failsafe after "
        f"{failsafe_after_s:.2f} s (COM_OF_LOSS_T {of_loss_t:.1f}), lost shown after "
        f"{detect_s:.2f} s, back {recover_s:.2f} s after the heal, fresh {fresh_s:.2f} s "
        f"later; report: {report['text']}"
    )
