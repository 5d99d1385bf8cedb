"""A vehicle that never confirms a new signing key, over real UDP through the fault proxy.

POST /api/v1/signing answers 504 after PROVISION_TRIES x PROVISION_CONFIRM_S and the link
and the key file go back to the key they had. Two ways to get there:

- the SETUP_SIGNING never reaches the vehicle (everything towards it dropped): the vehicle
  keeps its old key (here: none), so after the heal both ends still agree;
- the vehicle takes the new key but every answer is lost (everything towards the server
  dropped). The vehicle has switched; the server, which never heard it, goes back to the
  old key. Left there, each end would drop the other's frames (HEARTBEAT too, as it comes
  badly signed) and the vehicle would be gone for good. So after its last try the server
  sends SETUP_SIGNING with the old key signed with the new one: a vehicle that switched
  goes back, one that did not drops it. After the heal the link talks with the old key.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from server.link.codec.signing import MAVLINK_MSG_ID_SETUP_SIGNING
from server.link.codec.signing_provision import PROVISION_CONFIRM_S, PROVISION_TRIES
from sim.process.runner import SimInstance
from tests.api.conftest import Api
from tests.api.test_signing import post, signing_sim
from tests.faults.conftest import api_through, vehicle_behind_proxy
from tests.waiting import wait_for
from tools.faultproxy import FaultProxy

EXPECTED_S = PROVISION_TRIES * PROVISION_CONFIRM_S


@dataclass
class Rig:
    api: Api
    proxy: FaultProxy
    vehicle: SimInstance
    key_file: Path
    setups_sent: list[float]  # when the link sent a SETUP_SIGNING (monotonic)


@contextlib.asynccontextmanager
async def rig(tmp_path: Path) -> AsyncIterator[Rig]:
    key_file = tmp_path / "keys" / "signing.key"
    setups: list[float] = []
    async with (
        signing_sim(tmp_path) as sim,
        vehicle_behind_proxy(sim) as proxy,
        # a 4.5 s provisioning with nothing heard must not drop the vehicle meanwhile
        api_through(proxy, sim, signing_key_file=key_file, heartbeat_timeout_s=15.0) as api,
    ):
        link = api.app.state.api.registry.links[0]
        send = link.send

        def recording_send(msg: Any) -> None:
            if msg.get_msgId() == MAVLINK_MSG_ID_SETUP_SIGNING:
                setups.append(time.monotonic())
            send(msg)

        link.send = recording_send
        await api.wait_ready()
        await api.take_control()
        yield Rig(api, proxy, sim.instances[0], key_file, setups)


async def status(api: Api) -> dict[str, object]:
    body: dict[str, object] = (await api.client.get("/api/v1/signing")).json()
    return body


async def timed_504(rig: Rig, action: str) -> float:
    start = time.monotonic()
    response = await post(rig.api, action)
    elapsed = time.monotonic() - start
    assert response.status_code == 504, response.text
    reason = response.json()["detail"]["reason"]
    assert "never answered signed with the new key" in reason, reason
    assert f"{PROVISION_TRIES} SETUP_SIGNING sent" in reason
    assert "keeps its previous key" in reason
    # the three tries, each waiting PROVISION_CONFIRM_S (generous above: a loaded machine)
    assert EXPECTED_S - 0.1 <= elapsed < EXPECTED_S + 10.0, elapsed
    return elapsed


async def heard_since(api: Api, healed: float) -> None:
    """Until a HEARTBEAT came after the heal, as a pilot waits for the link to come back
    before arming (a loaded machine may take a while to move what the outage held)."""
    def heard(state: dict[str, Any]) -> bool:
        age_s = state["last_heartbeat_age_s"]
        return age_s is not None and age_s < time.monotonic() - healed

    await api.wait_state(heard, 15.0, "a HEARTBEAT after the heal")


async def arm_and_disarm(api: Api, vehicle: SimInstance) -> None:
    armed = await api.control("arm")
    assert armed.status_code == 200, armed.text
    assert vehicle.vehicle.commander.armed
    disarmed = await api.control("disarm", {"force": True})
    assert disarmed.status_code == 200, disarmed.text
    await api.wait_state(lambda s: not s["armed"], 10.0, "disarmed")


async def test_setup_signing_that_never_reaches_the_vehicle_is_a_504_and_no_key(
    tmp_path: Path,
) -> None:
    async with rig(tmp_path) as r:
        assert r.vehicle.signing is not None
        assert not r.vehicle.signing.enabled
        dropped = r.proxy.counters()["to_vehicle"].partitioned
        r.proxy.partition(60.0, "to_vehicle")
        elapsed = await timed_504(r, "generate")
        # every try went out and was dropped on the way; the vehicle never heard of a key
        assert len(r.setups_sent) == 2 * PROVISION_TRIES  # the tries, then the roll-back
        assert r.proxy.counters()["to_vehicle"].partitioned > dropped
        assert not r.vehicle.signing.enabled
        assert not r.key_file.exists()
        body = await status(r.api)
        assert body["enabled"] is False
        links = body["links"]
        assert isinstance(links, list)
        assert links[0]["signing"]["enabled"] is False

        r.proxy.heal()
        healed = time.monotonic()
        await heard_since(r.api, healed)
        await arm_and_disarm(r.api, r.vehicle)
        print(f"\nSETUP_SIGNING never delivered: 504 after {elapsed:.2f} s "
              f"(expected {EXPECTED_S:.1f} s); {len(r.setups_sent)} SETUP_SIGNING sent "
              f"(tries + roll-back); "
              f"arm+disarm after the heal in {time.monotonic() - healed:.2f} s")


async def test_a_rotation_whose_answers_are_lost_is_a_504_and_both_ends_keep_the_old_key(
    tmp_path: Path,
) -> None:
    async with rig(tmp_path) as r:
        assert (await post(r.api, "generate")).status_code == 200
        old_key = bytes.fromhex(r.key_file.read_text().strip())
        assert r.vehicle.signing is not None
        assert r.vehicle.signing.secret_key == old_key
        applied: list[bytes | None] = []
        handle = r.vehicle.signing.handle_setup_signing

        def recording(msg: object) -> bool:
            taken = handle(msg)
            if taken:
                applied.append(r.vehicle.signing.secret_key if r.vehicle.signing else None)
            return taken

        r.vehicle.signing.handle_setup_signing = recording  # type: ignore[method-assign]
        r.setups_sent.clear()
        r.proxy.partition(60.0, "to_server")
        elapsed = await timed_504(r, "rotate")
        assert len(r.setups_sent) == 2 * PROVISION_TRIES

        # the vehicle did take the new key (only its answers were lost), then the old one back
        assert len(applied) == 2, applied
        assert applied[0] != old_key
        assert applied[1] == old_key
        assert r.vehicle.signing.secret_key == old_key
        assert bytes.fromhex(r.key_file.read_text().strip()) == old_key
        body = await status(r.api)
        assert body["enabled"] is True

        r.proxy.heal()
        healed = time.monotonic()
        await r.api.wait_state(lambda s: s["link"]["signing"]["vehicles_signed"], 10.0,
                               "the vehicle talking with the old key after the heal")
        signed_again = time.monotonic() - healed
        await heard_since(r.api, healed)
        await arm_and_disarm(r.api, r.vehicle)
        await wait_for(lambda: r.vehicle.signing is not None
                       and r.vehicle.signing.secret_key == old_key, 1.0, "old key kept")
        print(f"\nrotation answers lost: 504 after {elapsed:.2f} s (expected {EXPECTED_S:.1f} s); "
              f"{len(r.setups_sent)} SETUP_SIGNING sent (tries + roll-back), "
              f"the vehicle applied {len(applied)} "
              f"(new key, then the old one back); signed with the old key "
              f"{signed_again:.2f} s after the heal")
