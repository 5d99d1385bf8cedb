"""A census of the simulated vehicle's telemetry held to PX4 v1.16 SITL's.

Every message id the sim sends on each link over a window of sim time, rate = count / time,
compared with the census of a real PX4 v1.16 SITL (SIH quad, standard VTOL and airplane, on
the ground, ready to arm; ../shared/PX4_NOTES.md "Telemetry PX4 sends", docs/sim.md). A type
agrees when it is there and its rate is within ±25%; at least 90% of PX4's types must agree
on each link. The sim runs its real airframe models, stepped in sim time (no wall clock).
"""

from __future__ import annotations

from collections import Counter

import pytest

from sim.vehicle import PHYSICS_DT_S, READY_TIME_S, SimVehicle
from tests.sim.conftest import Harness

WINDOW_S = 12.0
RATE_TOLERANCE = 0.25
AGREEMENT_NEEDED = 0.9

# PX4 v1.16 SITL's onboard link (its API port pair), Hz by message id
PX4_ONBOARD_HZ: dict[int, float] = {
    30: 100.0,  # ATTITUDE
    31: 50.0,  # ATTITUDE_QUATERNION
    33: 50.0,  # GLOBAL_POSITION_INT
    105: 50.0,  # HIGHRES_IMU
    32: 30.0,  # LOCAL_POSITION_NED
    331: 30.0,  # ODOMETRY
    141: 10.0,  # ALTITUDE
    83: 10.0,  # ATTITUDE_TARGET
    132: 10.0,  # DISTANCE_SENSOR
    85: 10.0,  # POSITION_TARGET_LOCAL_NED
    36: 10.0,  # SERVO_OUTPUT_RAW
    111: 10.0,  # TIMESYNC
    74: 10.0,  # VFR_HUD
    24: 8.0,  # GPS_RAW_INT
    245: 5.0,  # EXTENDED_SYS_STATE
    1: 5.0,  # SYS_STATUS
    230: 1.0,  # ESTIMATOR_STATUS
    0: 1.0,  # HEARTBEAT
    42: 1.0,  # MISSION_CURRENT
    12901: 1.0,  # OPEN_DRONE_ID_LOCATION
    12904: 1.0,  # OPEN_DRONE_ID_SYSTEM
    4: 1.0,  # PING
    29: 1.0,  # SCALED_PRESSURE
    2: 1.0,  # SYSTEM_TIME
    8: 1.0,  # LINK_NODE_STATUS
    147: 0.5,  # BATTERY_STATUS
    436: 0.5,  # CURRENT_MODE
    242: 0.5,  # HOME_POSITION
    241: 0.5,  # VIBRATION
    380: 0.5,  # TIME_ESTIMATE_TO_TARGET
    411: 0.35,  # CURRENT_EVENT_SEQUENCE
}

# PX4 v1.16 SITL's GCS link (its shared GCS port): normal mode with SITL's raised rates
PX4_GCS_HZ: dict[int, float] = {
    30: 50.0,  # ATTITUDE
    31: 50.0,  # ATTITUDE_QUATERNION
    83: 50.0,  # ATTITUDE_TARGET
    33: 50.0,  # GLOBAL_POSITION_INT
    32: 50.0,  # LOCAL_POSITION_NED
    85: 50.0,  # POSITION_TARGET_LOCAL_NED
    36: 50.0,  # SERVO_OUTPUT_RAW
    24: 5.0,  # GPS_RAW_INT
    74: 4.0,  # VFR_HUD
    0: 1.0,  # HEARTBEAT
    1: 1.0,  # SYS_STATUS
    245: 1.0,  # EXTENDED_SYS_STATE
    141: 1.0,  # ALTITUDE
    29: 1.0,  # SCALED_PRESSURE
    42: 1.0,  # MISSION_CURRENT
    12901: 1.0,  # OPEN_DRONE_ID_LOCATION
    12904: 1.0,  # OPEN_DRONE_ID_SYSTEM
    8: 1.0,  # LINK_NODE_STATUS
    147: 0.5,  # BATTERY_STATUS
    436: 0.5,  # CURRENT_MODE
    132: 0.5,  # DISTANCE_SENSOR
    230: 0.5,  # ESTIMATOR_STATUS
    242: 0.5,  # HOME_POSITION
    380: 0.5,  # TIME_ESTIMATE_TO_TARGET
    411: 0.35,  # CURRENT_EVENT_SEQUENCE
    4: 0.1,  # PING
    241: 0.1,  # VIBRATION
}


# sent as things happen, not streamed: EVENT, STATUSTEXT, COMMAND_ACK, PARAM_VALUE
AS_IT_HAPPENS = frozenset({410, 253, 77, 22})

# A fixed-wing PX4 (SIH airplane) adds the fixed-wing position controller's status
NAV_CONTROLLER_OUTPUT = 62
PX4_HZ_BY_AIRFRAME: dict[str, tuple[dict[int, float], dict[int, float]]] = {
    "quad": (PX4_ONBOARD_HZ, PX4_GCS_HZ),
    "vtol": (PX4_ONBOARD_HZ, PX4_GCS_HZ),
    "plane": ({**PX4_ONBOARD_HZ, NAV_CONTROLLER_OUTPUT: 10.0},
              {**PX4_GCS_HZ, NAV_CONTROLLER_OUTPUT: 1.0}),
}

Census = tuple[str, dict[int, float], dict[int, float]]


def message_id(msg: object) -> int:
    """The id of a decoded message; pymavlink names ids outside its dialect UNKNOWN_<id>."""
    name: str = msg.get_type()  # type: ignore[attr-defined]
    if name.startswith("UNKNOWN_"):
        return int(name.removeprefix("UNKNOWN_"))
    return int(msg.get_msgId())  # type: ignore[attr-defined]


def census(messages: list[object], seconds: float) -> dict[int, float]:
    counts = Counter(message_id(m) for m in messages)
    return {msg_id: n / seconds for msg_id, n in counts.items()}


def disagreements(measured: dict[int, float], px4: dict[int, float]) -> dict[int, str]:
    """PX4's message types the sim misses or sends at another rate (beyond ±25%)."""
    wrong: dict[int, str] = {}
    for msg_id, hz in px4.items():
        got = measured.get(msg_id, 0.0)
        if abs(got - hz) > RATE_TOLERANCE * hz:
            wrong[msg_id] = f"{got:.2f} Hz, PX4 {hz} Hz"
    return wrong


@pytest.fixture(scope="module", params=list(PX4_HZ_BY_AIRFRAME))
def sim_census(request: pytest.FixtureRequest) -> Census:
    """(airframe, onboard, GCS census) of a ready vehicle on the ground with its real
    airframe model."""
    harness = Harness(SimVehicle(request.param))
    harness.run_until(lambda: harness.vehicle.ready, READY_TIME_S + 2.0)
    harness.run(2.0)  # settled: home set, every stream past its first slot
    harness.api.clear()
    harness.gcs.clear()
    for _ in range(round(WINDOW_S / PHYSICS_DT_S)):
        harness.vehicle.step(PHYSICS_DT_S)
    return request.param, census(harness.api.sent, WINDOW_S), census(harness.gcs.sent, WINDOW_S)


@pytest.mark.parametrize("link", [0, 1], ids=["onboard", "gcs"])
def test_census_agrees_with_px4_for_nine_in_ten_types(sim_census: Census, link: int) -> None:
    airframe, *measured = sim_census
    px4 = PX4_HZ_BY_AIRFRAME[airframe][link]
    wrong = disagreements(measured[link], px4)
    agreeing = 1.0 - len(wrong) / len(px4)
    assert agreeing >= AGREEMENT_NEEDED, wrong


@pytest.mark.parametrize("link", [0, 1], ids=["onboard", "gcs"])
def test_census_sends_nothing_px4_does_not(sim_census: Census, link: int) -> None:
    airframe, *measured = sim_census
    streamed = set(measured[link]) - AS_IT_HAPPENS
    assert streamed - set(PX4_HZ_BY_AIRFRAME[airframe][link]) == set()
