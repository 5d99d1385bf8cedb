"""Cost of the state JSON: µs to encode one full snapshot the way the API sends it (goal
≤ 40 µs), and encodes per publisher tick with 1 and with 50 telemetry subscribers of one
vehicle (goal: one per tick, whatever the number of subscribers).

Run: .venv/bin/python -m bench.state_encode
Writes bench/results/state_encode.json.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import os
import statistics
import time
from typing import Any

from bench._markdown import ratio, table
from bench._report import Section, save_figure
from bench._results import machine_info, write_results
from server.control.publisher import Published, StatePublisher
from server.control.slots import Slot
from server.control.views import encode_state, state_json, state_message
from server.link.core import state as link
from server.link.core.link_stats import LinkStats
from tests.api.state_fakes import PushingVehicle

GOAL_US = 40.0
ENCODES_PER_ROUND = 2000
ROUNDS = 7
PUBLISHER_RATE_HZ = 50.0
CHANGE_RATE_HZ = 100.0
FAN_OUT_S = 2.0
LEASE = ("dashboard", 1.5)


def full_state(north_m: float = 12.5) -> link.VehicleState:
    """A snapshot with every optional part present, as a flying vehicle reports it."""
    return link.VehicleState(
        sysid=1, compid=1, mav_type="QUADROTOR", autopilot="PX4", connected=True,
        last_heartbeat_age_s=0.21, mode="OFFBOARD", user_mode="OFFBOARD", armed=True,
        ready_to_arm=True,
        system_status="ACTIVE", landed_state="IN_AIR", vtol_state="UNDEFINED",
        position_ned=link.PositionNedState(north_m, -3.25, -10.0),
        velocity_ned=link.VelocityNedState(1.5, -0.25, 0.05),
        global_position=link.GlobalState(47.3978541, 8.5455923, 498.2, 10.0),
        attitude=link.AttitudeState(1.2, -0.8, 87.5, 0.1, -0.2, 0.5),
        ground_speed_m_s=1.52, air_speed_m_s=float("nan"), climb_rate_m_s=-0.05,
        heading_deg=87.0, battery=link.BatteryState(16.1, 12.4, 81.0, 412.0, 1260.0),
        gps=link.GpsState("3D_FIX", 14, 0.8),
        home=link.HomeState(47.397742, 8.545594, 488.0, 0.0, 0.0, 0.0),
        origin=link.OriginState(47.397742, 8.545594, 488.0),
        setpoint={"type": "position_ned", "north_m": 15.0, "east_m": -3.0, "down_m": -10.0,
                  "yaw_deg": float("nan")},
        target_ned=link.PositionNedState(15.0, -3.0, -10.0),
        stream=link.StreamStats(True, 20.0, 50.0, 51.2, 55.0, 0, 4312, 12.0),
        actuator_outputs=(0.52, 0.55, 0.51, 0.56),
        statustext=tuple(link.StatusText(100.0 + i, "INFO", f"message {i}") for i in range(5)),
        rtl_phase=None,
        link=LinkStats("udpin:0.0.0.0:14540", True, 123456, 23456, 4567890, 345678, 3, 0, 0.21, 0),
        updated_s=1234.5,
        telemetry_refused=(),
        estimator=link.EstimatorState(
            ("ATTITUDE", "VELOCITY_HORIZ", "VELOCITY_VERT", "POS_HORIZ_REL", "POS_HORIZ_ABS",
             "POS_VERT_ABS", "POS_VERT_AGL", "PRED_POS_HORIZ_REL", "PRED_POS_HORIZ_ABS"),
            True, 0.02, 0.05, 0.1,
        ),
        sensors_unhealthy=(),
        message_ages_s={kind: 0.001 * i for i, kind in enumerate((
            "HEARTBEAT", "CURRENT_MODE", "EXTENDED_SYS_STATE", "LOCAL_POSITION_NED",
            "GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD", "SYS_STATUS", "BATTERY_STATUS",
            "GPS_RAW_INT", "HOME_POSITION", "GPS_GLOBAL_ORIGIN", "POSITION_TARGET_LOCAL_NED",
            "SERVO_OUTPUT_RAW", "STATUSTEXT", "ESTIMATOR_STATUS",
        ))},
    )  # fmt: skip


def _us_per_call(call: Any) -> float:
    rounds = []
    for _ in range(ROUNDS):
        started = time.perf_counter()
        for _ in range(ENCODES_PER_ROUND):
            call()
        rounds.append((time.perf_counter() - started) / ENCODES_PER_ROUND * 1e6)
    return statistics.median(rounds)


def measure_encode() -> dict[str, Any]:
    state = full_state()
    body = encode_state(state)
    return {
        "bytes": len(state_message(state, body, LEASE)),
        "encode_us": round(_us_per_call(lambda: encode_state(state)), 1),
        "ws_message_us": round(
            _us_per_call(lambda: state_message(state, encode_state(state), LEASE)), 1
        ),
        "rest_body_us": round(
            _us_per_call(lambda: state_json(state, encode_state(state), LEASE)), 1
        ),
        "asdict_json_dumps_us": round(
            _us_per_call(lambda: json.dumps(dataclasses.asdict(state))), 1
        ),
    }


async def _read(slot: Slot[Published], counts: list[int]) -> None:
    async for published in slot:
        _ = published.message  # what a telemetry socket sends
        counts[0] += 1


async def measure_fan_out(subscribers: int) -> dict[str, Any]:
    vehicle = PushingVehicle(lambda v: full_state(0.1 * v.moves))
    publisher = StatePublisher(vehicle, lambda _: LEASE, max_rate_hz=PUBLISHER_RATE_HZ)
    publisher.start()
    await asyncio.sleep(0.05)
    counts = [[0] for _ in range(subscribers)]
    readers = [
        asyncio.create_task(_read(publisher.subscribe(PUBLISHER_RATE_HZ), count))
        for count in counts
    ]
    started = time.perf_counter()
    while time.perf_counter() - started < FAN_OUT_S:
        vehicle.move()
        await asyncio.sleep(1.0 / CHANGE_RATE_HZ)
    await asyncio.sleep(0.3)
    await publisher.close()
    await asyncio.gather(*readers)
    delivered = sum(count[0] for count in counts)
    return {
        "subscribers": subscribers,
        "ticks": publisher.ticks,
        "encodes": publisher.encodes,
        "encodes_per_tick": round(publisher.encodes / publisher.ticks, 3),
        "messages_sent": delivered,
        "messages_per_encode": round(delivered / max(1, publisher.encodes), 1),
    }


def main() -> int:
    load_before = os.getloadavg()
    encode = measure_encode()
    print(
        f"state encode: {encode['encode_us']} µs (goal ≤ {GOAL_US:.0f}), WS message "
        f"{encode['ws_message_us']} µs, REST body {encode['rest_body_us']} µs, "
        f"{encode['bytes']} bytes; dataclasses.asdict + json.dumps "
        f"{encode['asdict_json_dumps_us']} µs"
    )
    fan_out = [asyncio.run(measure_fan_out(n)) for n in (1, 50)]
    for row in fan_out:
        print(
            f"{row['subscribers']:>2} subscriber(s): {row['ticks']} ticks, {row['encodes']} "
            f"encodes ({row['encodes_per_tick']} per tick), {row['messages_sent']} messages sent"
        )
    result = {
        "goal_us": GOAL_US,
        "encode": encode,
        "within_goal": encode["ws_message_us"] <= GOAL_US,
        "fan_out": fan_out,
        "one_encode_per_tick": all(row["encodes"] <= row["ticks"] for row in fan_out)
        and fan_out[0]["encodes_per_tick"] == fan_out[-1]["encodes_per_tick"],
        "machine": machine_info(load_before),
    }
    write_results("state_encode", result)
    return 0 if result["within_goal"] and result["one_encode_per_tick"] else 1


if __name__ == "__main__":
    raise SystemExit(main())


def report(result: dict[str, Any]) -> Section | None:
    """Encode cost against the naive encode, and encodes per tick with 1 and 50 readers."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    enc = result["encode"]
    labels = ["encode_state", "WS message", "REST body", "asdict + json.dumps"]
    values = [enc["encode_us"], enc["ws_message_us"], enc["rest_body_us"],
              enc["asdict_json_dumps_us"]]
    fig = Figure(figsize=(6.4, 3.0))
    ax = fig.add_subplot()
    bars = ax.barh(labels[::-1], values[::-1],
                   color=["#999999", "#4c72b0", "#4c72b0", "#4c72b0"])
    ax.bar_label(bars, fmt="%.1f µs", padding=3)
    ax.axvline(result["goal_us"], color="#c44e52", linestyle="--",
               label=f"goal {result['goal_us']:.0f} µs")
    ax.set_xlabel(f"µs per full vehicle snapshot ({enc['bytes']} bytes)")
    ax.set_xlim(0, max(values) * 1.25)
    ax.legend(loc="upper right")
    figure = save_figure(fig, "state_encode", "Cost of one state snapshot as the API sends it",
                         result["machine"])
    rows = [[r["subscribers"], r["ticks"], r["encodes"], r["encodes_per_tick"],
             r["messages_sent"], r["messages_per_encode"]] for r in result["fan_out"]]
    first, last = result["fan_out"][0], result["fan_out"][-1]
    cost = ratio(enc["ws_message_us"], enc["asdict_json_dumps_us"])
    markdown = (
        f"A WebSocket state message costs **{cost}"
        f"** of `json.dumps(dataclasses.asdict(state))` ({enc['ws_message_us']} µs vs "
        f"{enc['asdict_json_dumps_us']} µs; goal ≤ {result['goal_us']:.0f} µs: "
        f"{'met' if result['within_goal'] else 'NOT met'}). With {last['subscribers']} "
        f"subscribers the publisher encodes {last['encodes_per_tick']} times per tick, as with "
        f"{first['subscribers']} ({first['encodes_per_tick']}): one encode per tick shared by "
        f"every reader ({'met' if result['one_encode_per_tick'] else 'NOT met'}).\n\n"
        + table(["subscribers", "ticks", "encodes", "encodes/tick", "messages sent",
                 "messages/encode"], rows)
    )
    return Section("State encoding and fan-out", 40, markdown, [figure])
