"""PX4's decoded events through the API, on the simulated vehicle: the reasons of refused
arming and mode switches, and a failsafe as a WS event and a line of the state's log."""

from __future__ import annotations

from websockets.asyncio.client import connect

from tests.api.conftest import Api
from tests.api.test_ws import fly_offboard_at_2_m_s, receive_until, served
from tests.waiting import eventually

NO_OFFBOARD_SIGNAL = "No offboard signal"
FAILSAFE_TEXT = "Failsafe activated: switching to Position mode"


async def _decoding(api: Api) -> None:
    async def loaded() -> bool:
        return api.vehicle().px4_events.decoder is not None

    await eventually(loaded, 10.0, "the vehicle's events metadata")


async def test_arming_refusal_in_the_pilots_mode_is_409_with_px4s_text(quad_api: Api) -> None:
    api = quad_api
    await _decoding(api)
    await api.take_control()
    # the pilot's own choice, with a check failing in it (no mission; PX4 reports it as a
    # notice): the server never switches away from it
    assert (await api.control("mode", {"mode": "MISSION"})).status_code == 200

    arm = await api.control("arm")

    assert arm.status_code == 409, arm.text
    assert arm.json()["reason"] == "Arming denied: Resolve system health failures first"
    assert (await api.state())["mode"] == "MISSION"


async def test_offboard_refused_in_flight_names_the_missing_offboard_signal(
    quad_api: Api,
) -> None:
    api = quad_api
    await _decoding(api)
    await api.take_control()
    assert (await api.control("arm")).status_code == 200
    assert (await api.control("takeoff", {"altitude_m": 3.0})).status_code == 200
    await api.wait_state(lambda s: s["mode"] == "HOLD" and s["landed_state"] == "IN_AIR",
                         20.0, "takeoff done")  # fmt: skip

    refused = await api.control("mode", {"mode": "OFFBOARD"})  # no setpoint stream

    assert refused.status_code == 409, refused.text
    assert refused.json()["reason"] == (
        f"Switching to mode 'Offboard' is currently not possible: {NO_OFFBOARD_SIGNAL}"
    )


async def test_offboard_loss_failsafe_reaches_the_ws_and_the_log() -> None:
    async with served() as s:
        await _decoding(s.api)
        async with connect(s.url("telemetry", vehicle=1, rate_hz=1)) as telemetry:
            pilot = await fly_offboard_at_2_m_s(s)
            s.api.vehicle().offboard.close()  # the setpoint stream stops in OFFBOARD

            event = await receive_until(telemetry, {"type": "event", "kind": "px4_event"})
            while event["data"]["name"] != "commander_failsafe_enter_generic":
                event = await receive_until(telemetry, {"type": "event", "kind": "px4_event"})
            # the mode shows with the next HEARTBEAT / CURRENT_MODE, after the event
            await s.api.wait_state(lambda st: st["mode"] == "POSCTL", 10.0, "Position failsafe")
            await pilot.close()

        assert event["data"]["text"] == FAILSAFE_TEXT
        assert event["data"]["log_level"] == "CRITICAL"
        state = await s.api.state()
        log = [(m["severity"], m["text"]) for m in state["statustext"]]
        assert ("CRITICAL", FAILSAFE_TEXT) in log
        assert ("CRITICAL", "Failsafe activated") in log  # PX4's own STATUSTEXT for it
