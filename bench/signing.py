"""MAVLink 2 signing: what it costs and how fast a key is set or rotated.

1. Codec cost per frame (pymavlink, this machine): pack and decode of
   SET_POSITION_TARGET_LOCAL_NED, unsigned vs signed (signed decode = HMAC check + window).
2. Against the simulated vehicle over UDP (in-process, keys in a temporary directory):
   time for SETUP_SIGNING to be confirmed (first key, then a rotation), frames the link
   rejected while switching, the vehicle's frame rate reaching the link and the arm → ACK
   round trip, unsigned vs signed.

    .venv/bin/python -m bench.signing
"""

from __future__ import annotations

import asyncio
import os
import secrets
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import development as mavlink

from bench._markdown import ratio, table
from bench._report import Section
from bench._results import machine_info, write_results
from server.link import Link, Vehicle
from server.link.codec.signing_keys import SigningKeyStore, signing_timestamp
from server.link.codec.signing_provision import provision
from sim.process.runner import SimCluster

CODEC_FRAMES = 20_000
RATE_WINDOW_S = 3.0
ARM_ROUNDS = 10


def codec_cost_us() -> dict[str, float]:
    msg = mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, 1, 0b0000111111000111, 1.0, 2.0, -3.0, 0, 0, 0, 0, 0, 0, 0.5, 0)
    result: dict[str, float] = {}
    for label, key in (("unsigned", None), ("signed", secrets.token_bytes(32))):
        sender = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        receiver = mavlink.MAVLink(None)
        if key is not None:
            for mav in (sender, receiver):
                mav.signing.secret_key = key
            sender.signing.sign_outgoing = True
            sender.signing.timestamp = signing_timestamp()
        started = time.perf_counter()
        frames = [bytes(msg.pack(sender)) for _ in range(CODEC_FRAMES)]
        packed = time.perf_counter()
        for frame in frames:
            receiver.parse_buffer(frame)
        decoded = time.perf_counter()
        result[f"pack_{label}_us"] = (packed - started) / CODEC_FRAMES * 1e6
        result[f"decode_{label}_us"] = (decoded - packed) / CODEC_FRAMES * 1e6
    return result


async def frame_rate(link: Link) -> float:
    before = link.stats().frames_in
    await asyncio.sleep(RATE_WINDOW_S)
    return (link.stats().frames_in - before) / RATE_WINDOW_S


async def arm_round_trip_ms(vehicle: Vehicle) -> float:
    times = []
    for _ in range(ARM_ROUNDS):
        started = time.perf_counter()
        result = await vehicle.arm()
        times.append((time.perf_counter() - started) * 1e3)
        assert result.ok, result
        await vehicle.disarm(force=True)
        await vehicle.wait_until(lambda: not vehicle.snapshot().armed, 5.0)
    return statistics.median(times)


async def against_sim(tmp: Path) -> dict[str, Any]:
    figures: dict[str, Any] = {}
    async with SimCluster(airframe="quad", speed=1.0, signing_dir=tmp / "sim") as sim:
        await sim.wait_ready(timeout_s=30.0)
        store = SigningKeyStore(tmp / "signing.key")
        link = await Link.open(f"udpout:127.0.0.1:{sim.instances[0].api_local_port}",
                               log_dir=None, signing_store=store)
        try:
            vehicle = await asyncio.wait_for(link.subscribe_vehicles().get(), 30.0)
            await asyncio.sleep(2.0)  # telemetry requests settle
            figures["frames_per_s_unsigned"] = await frame_rate(link)
            figures["arm_ack_ms_unsigned"] = await arm_round_trip_ms(vehicle)
            started = time.perf_counter()
            await provision(link, [1], secrets.token_bytes(32))
            figures["provision_first_key_ms"] = (time.perf_counter() - started) * 1e3
            figures["frames_per_s_signed"] = await frame_rate(link)
            figures["arm_ack_ms_signed"] = await arm_round_trip_ms(vehicle)
            stats = link.stats().signing
            assert stats is not None
            rejected_before = stats.rejected
            started = time.perf_counter()
            await provision(link, [1], secrets.token_bytes(32))
            figures["rotation_ms"] = (time.perf_counter() - started) * 1e3
            stats = link.stats().signing
            assert stats is not None
            figures["frames_rejected_during_rotation"] = stats.rejected - rejected_before
            figures["vehicle_connected_after_rotation"] = vehicle.connected
        finally:
            await link.close()
    return figures


def main() -> None:
    load_before = os.getloadavg()
    codec = codec_cost_us()
    with tempfile.TemporaryDirectory() as tmp:
        sim = asyncio.run(against_sim(Path(tmp)))
    for name, value in {**codec, **sim}.items():
        print(f"{name:36s} {value:.2f}" if isinstance(value, float) else f"{name:36s} {value}")
    write_results("signing", {"codec": codec, "sim": sim,
                              "machine": machine_info(load_before)})


if __name__ == "__main__":
    main()


def report(result: dict[str, Any]) -> Section | None:
    """Signed vs unsigned, per frame and against the simulated vehicle."""
    codec, sim = result["codec"], result["sim"]
    rows = [
        ["pack SET_POSITION_TARGET_LOCAL_NED (µs)", f"{codec['pack_unsigned_us']:.1f}",
         f"{codec['pack_signed_us']:.1f}",
         ratio(codec["pack_signed_us"], codec["pack_unsigned_us"])],
        ["decode (µs; signed: HMAC + window)", f"{codec['decode_unsigned_us']:.1f}",
         f"{codec['decode_signed_us']:.1f}",
         ratio(codec["decode_signed_us"], codec["decode_unsigned_us"])],
        ["vehicle frames/s reaching the link", f"{sim['frames_per_s_unsigned']:.0f}",
         f"{sim['frames_per_s_signed']:.0f}",
         ratio(sim["frames_per_s_signed"], sim["frames_per_s_unsigned"])],
        ["arm → ACK (ms)", f"{sim['arm_ack_ms_unsigned']:.2f}", f"{sim['arm_ack_ms_signed']:.2f}",
         ratio(sim["arm_ack_ms_signed"], sim["arm_ack_ms_unsigned"])],
    ]
    decode = ratio(codec["decode_signed_us"], codec["decode_unsigned_us"])
    markdown = (
        f"Signing makes a frame's decode {decode}"
        f" as costly and leaves the vehicle's frame rate at "
        f"{ratio(sim['frames_per_s_signed'], sim['frames_per_s_unsigned'])} of unsigned. The "
        f"first key is confirmed in {sim['provision_first_key_ms']:.0f} ms, a rotation in "
        f"{sim['rotation_ms']:.0f} ms, with {sim['frames_rejected_during_rotation']} frames "
        f"rejected while switching (vehicle still connected: "
        f"{'yes' if sim['vehicle_connected_after_rotation'] else 'NO'}).\n\n"
        + table(["", "unsigned", "signed", "signed / unsigned"], rows))
    return Section("MAVLink 2 signing", 95, markdown)
