"""The vehicle reboots mid-flight (the simulated PX4 stopped and started again with the same
sysid, behind the fault proxy): SkyHelm notices it, stops streaming, asks again for its
telemetry streams, reads its parameters and its events metadata again, and shows nothing
from before the reboot as live."""

from __future__ import annotations

import time
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from tests.api.conftest import Api, api_for
from tests.faults.linkloss_rig import proxied_sim, rest_state
from tests.waiting import eventually, wait_for

CLIMB_TO = {"type": "position_ned", "north_m": 0.0, "east_m": 0.0, "down_m": -4.0}


class _CommandTap:
    """COMMAND_LONGs the proxy passed on to the vehicle, by arrival time."""

    def __init__(self) -> None:
        self.parser = mavlink.MAVLink(None)
        self.commands: list[tuple[float, int]] = []
        self.param_reads: list[tuple[float, str]] = []

    def __call__(self, direction: str, payload: bytes) -> None:
        if direction != "to_vehicle":
            return
        for msg in self.parser.parse_buffer(payload) or []:
            if msg.get_type() == "COMMAND_LONG":
                self.commands.append((time.monotonic(), msg.command))
            elif msg.get_type() == "PARAM_REQUEST_READ":
                self.param_reads.append((time.monotonic(), msg.param_id))

    def since(self, t: float, command: int) -> int:
        return sum(1 for at, c in self.commands if at >= t and c == command)


async def test_reboot_in_flight_renews_streams_params_metadata_and_state() -> None:
    async with proxied_sim() as rig, api_for(None, connect=[rig.url]) as api:
        await wait_for(lambda: api.app.state.api.registry.get(1) is not None, 10.0, "discovery")
        await api.wait_ready()
        vehicle = api.vehicle()
        await wait_for(lambda: vehicle.px4_events.decoder is not None, 10.0, "events metadata")
        tap = _CommandTap()
        rig.proxy.add_tap(tap)
        events = vehicle.subscribe_events(1024)
        await _fly_offboard(api)
        # a parameter the operator changed, which the vehicle forgets on reboot (the sim
        # keeps no parameter file)
        changed = await api.client.put(
            "/api/v1/vehicles/1/params/MIS_TAKEOFF_ALT", json={"value": 7.0},
            headers=api.lease_headers,
        )
        assert changed.status_code == 200, changed.text
        assert vehicle.params.cache["MIS_TAKEOFF_ALT"].value == 7.0
        old_decoder = vehicle.px4_events.decoder

        rebooted_at = time.monotonic()
        await rig.reboot()

        kinds: list[tuple[str, dict[str, object]]] = []

        def seen(kind: str) -> dict[str, object] | None:
            while not events.empty():
                event = events.get_nowait()
                kinds.append((event.kind, event.data))
            return next((d for k, d in kinds if k == kind), None)

        await wait_for(lambda: seen("reboot"), 15.0, "the reboot noticed")
        detect_s = time.monotonic() - rebooted_at
        reboot = seen("reboot")
        assert reboot is not None
        assert "boot time went back" in str(reboot["reason"])
        assert any(k == "stream" and d.get("reason") == "link lost" for k, d in kinds) or any(
            k == "stream" and d.get("reason") == "vehicle rebooted" for k, d in kinds
        ), kinds
        assert not vehicle.streamer_active

        # nothing from before is live: the new vehicle is on the ground, disarmed
        async def settled() -> dict[str, Any] | None:
            state = await rest_state(api.client)
            return state if state["connected"] and not state["stale"] else None

        state = await eventually(settled, 10.0, "fresh state after the reboot")
        recover_s = time.monotonic() - rebooted_at
        assert state["armed"] is False
        assert state["mode"] != "OFFBOARD"
        assert state["position_ned"]["down_m"] > -0.5
        assert state["stream"]["active"] is False
        # stream requests sent again to the new vehicle, and its home asked for again
        assert tap.since(rebooted_at, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL) >= 5
        await wait_for(lambda: api.vehicle().telemetry.home is not None, 10.0, "home again")
        # parameters read again: the cache holds the rebooted vehicle's value
        await wait_for(lambda: seen("params"), 10.0, "parameters read again")
        assert vehicle.params.cache["MIS_TAKEOFF_ALT"].value == 2.5
        assert any(at >= rebooted_at and name == "MIS_TAKEOFF_ALT"
                   for at, name in tap.param_reads)
        # the events metadata fetched again
        await wait_for(lambda: vehicle.px4_events.decoder is not None
                       and vehicle.px4_events.decoder is not old_decoder, 10.0, "metadata again")
        restored = seen("link_restored")
        assert restored is not None, kinds
        assert restored["rebooted"] is True
        print(f"\nreboot (sim restart): noticed after {detect_s:.2f} s, fresh state after "
              f"{recover_s:.2f} s; report: {restored['text']}")


async def _fly_offboard(api: Api) -> None:
    await api.take_control()
    assert (await api.control("arm")).status_code == 200
    start = await api.control("offboard/start", {"setpoint": CLIMB_TO})
    assert start.status_code == 200, start.text
    await api.wait_state(lambda s: s["position_ned"]["down_m"] < -3.0, 20.0, "climb to 3 m")
