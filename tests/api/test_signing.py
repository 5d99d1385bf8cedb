"""/api/v1/signing end to end: the app on a simulated vehicle over UDP gives it a key with
SETUP_SIGNING, rotates and removes it; the key file is the only place the key goes (not a
response, not the vehicle state); with signing on, an unsigned sender cannot arm the sim
while the server still can; a restart picks the link up signed."""

from __future__ import annotations

import asyncio
import contextlib
import secrets
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any, cast

from pymavlink.dialects.v20 import development as mavlink

from sim.process.runner import SimCluster
from tests.api.conftest import OBSERVER, Api, api_for, auth
from tests.sim.conftest import PointMassAirframe, point_mass_defaults
from tests.waiting import holds_for, wait_for


@contextlib.asynccontextmanager
async def signing_sim(tmp_path: Path) -> AsyncIterator[SimCluster]:
    async with SimCluster(airframe_factory=PointMassAirframe,
                          defaults_factory=point_mass_defaults, speed=8.0,
                          signing_dir=tmp_path / "sim") as sim:
        await sim.wait_ready(timeout_s=30.0)
        yield sim


async def post(api: Api, action: str, token: str | None = None) -> Any:
    headers = auth(token) if token else None
    return await api.client.post("/api/v1/signing", json={"action": action}, headers=headers)


class Stranger(asyncio.DatagramProtocol):
    """A plain pymavlink socket that sends unsigned commands."""

    def __init__(self) -> None:
        self.transport: asyncio.DatagramTransport | None = None
        self.mav = mavlink.MAVLink(None, srcSystem=250, srcComponent=190)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def send(self, msg: Any, port: int) -> None:
        assert self.transport is not None
        self.transport.sendto(bytes(msg.pack(self.mav)), ("127.0.0.1", port))


async def test_signing_without_a_key_file_is_refused_and_reported_off() -> None:
    async with api_for(None, connect=["udpin:127.0.0.1:0"]) as api:
        status = (await api.client.get("/api/v1/signing")).json()
        assert (status["enabled"], status["key_file_set"]) == (False, False)
        assert status["links"][0]["signing"]["enabled"] is False
        response = await post(api, "generate")
        assert response.status_code == 409
        assert "signing_key_file" in response.json()["detail"]["reason"]


async def test_generate_rotate_disable_and_an_unsigned_sender_cannot_arm(
    tmp_path: Path,
) -> None:
    key_file = tmp_path / "keys" / "signing.key"
    async with signing_sim(tmp_path) as sim, api_for(sim, signing_key_file=key_file) as api:
        inst = sim.instances[0]
        assert (await post(api, "generate", OBSERVER)).status_code == 403
        assert (await post(api, "rotate")).status_code == 409  # nothing to rotate yet
        response = await post(api, "generate")
        assert response.status_code == 200, response.text
        body = response.json()
        assert body["enabled"]
        assert body["links"][0]["signing"]["vehicles_signed"]
        first = key_file.read_text().strip()
        assert len(first) == 64
        assert first not in response.text
        assert inst.signing is not None
        assert inst.signing.secret_key == bytes.fromhex(first)
        state = await api.state()
        assert state["link"]["signing"]["enabled"] is True
        assert first not in str(state)

        # a stranger's unsigned arm is dropped; the server's signed one is taken
        loop = asyncio.get_running_loop()
        transport, stranger = await loop.create_datagram_endpoint(
            Stranger, local_addr=("127.0.0.1", 0))
        try:
            rejected = inst.signing.rejected
            stranger.send(mavlink.MAVLink_command_long_message(
                1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0),
                inst.api_local_port)
            await wait_for(lambda: inst.signing is not None
                           and inst.signing.rejected > rejected, 5.0, "refused")
            await holds_for(lambda: not inst.vehicle.armed, 0.3, "still disarmed")
        finally:
            transport.close()
        await api.take_control()
        armed = await api.control("arm")
        assert armed.status_code == 200, armed.text
        await api.wait_state(lambda s: s["armed"], 5.0, "armed")
        assert (await post(api, "rotate")).status_code == 409  # PX4: not while armed
        assert (await api.control("disarm", {"force": True})).status_code == 200
        await api.wait_state(lambda s: not s["armed"], 5.0, "disarmed")

        assert (await post(api, "generate")).status_code == 409  # already on
        response = await post(api, "rotate")
        assert response.status_code == 200, response.text
        second = key_file.read_text().strip()
        assert second != first
        assert inst.signing.secret_key == bytes.fromhex(second)
        assert (await api.state())["connected"] is True

        response = await post(api, "disable")
        assert response.status_code == 200, response.text
        assert response.json()["enabled"] is False
        assert not key_file.exists()
        assert not inst.signing.enabled


async def test_a_restarted_server_talks_signed_with_the_kept_key(tmp_path: Path) -> None:
    key_file = tmp_path / "signing.key"
    async with signing_sim(tmp_path) as sim:
        async with api_for(sim, signing_key_file=key_file) as api:
            assert (await post(api, "generate")).status_code == 200
        timestamp_file = key_file.with_name(key_file.name + ".timestamp")
        assert timestamp_file.exists()
        async with api_for(sim, signing_key_file=key_file) as api:
            status = await api.client.get("/api/v1/signing")
            assert status.json()["enabled"] is True
            await api.wait_state(lambda s: s["link"]["signing"]["vehicles_signed"], 10.0,
                                 "signed both ways after the restart")
            assert secrets.compare_digest(
                bytes.fromhex(key_file.read_text().strip()),
                sim.instances[0].signing.secret_key or b"",
            )
