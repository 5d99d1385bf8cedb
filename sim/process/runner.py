"""Run K simulated vehicles in this process, each with its two UDP links (PX4 SITL style).

Instance i has sysid i+1 and two sockets: the API/onboard link (PX4 SITL: from 14580+i
to 14540+i) and the GCS/normal link (from 18570+i to 14550). One asyncio task steps
all vehicles on absolute deadlines.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

from sim.mavlink.endpoint import UdpLink, open_link
from sim.mavlink.signing import MAVLINK_SECRET_FILE, VehicleSigning
from sim.process.clock import Clock
from sim.process.run_loop import FAST_FORWARD_SPEED, LoopStats, Pace, run_vehicles
from sim.vehicle import AirframeFactory, DefaultsFactory, SimVehicle

# Spacing of the instances' spawn points along east, so they do not start inside each other.
SPAWN_SPACING_M = 2.0


@dataclass
class SimInstance:
    instance: int
    sysid: int
    vehicle: SimVehicle
    api_link: UdpLink
    gcs_link: UdpLink
    signing: VehicleSigning | None = None

    @property
    def api_local_port(self) -> int:
        return self.api_link.local_port

    @property
    def gcs_local_port(self) -> int:
        return self.gcs_link.local_port

    @property
    def links(self) -> tuple[UdpLink, UdpLink]:
        return (self.api_link, self.gcs_link)

    @property
    def rx_dropped(self) -> int:
        """Garbage, truncated and bad-CRC datagram pieces dropped on both links."""
        return sum(link.counters.rx_dropped for link in self.links)

    @property
    def tx_unpackable(self) -> int:
        """Outgoing messages that could not be encoded and were skipped, on both links."""
        return sum(link.counters.tx_unpackable for link in self.links)

    def close(self) -> None:
        for link in self.links:
            link.close()
        if self.signing is not None:
            self.signing.close()


class SimCluster:
    """Async context manager: binds the sockets, runs the vehicles, closes everything."""

    def __init__(
        self,
        airframe: str = "quad",
        count: int = 1,
        instance: int = 0,
        host: str = "127.0.0.1",
        api_port: int | None = None,
        gcs_port: int | None = None,
        api_local_port: int = 0,
        gcs_local_port: int = 0,
        speed: float = 1.0,
        *,
        airframe_factory: AirframeFactory | None = None,
        defaults_factory: DefaultsFactory | None = None,
        clock: Clock | None = None,
        signing_dir: Path | None = None,
    ) -> None:
        if count < 1:
            raise ValueError("count must be at least 1")
        self.airframe = airframe
        self.count = count
        self.first_instance = instance
        self.host = host
        self.api_port = api_port
        self.gcs_port = gcs_port
        self.api_local_port = api_local_port
        self.gcs_local_port = gcs_local_port
        # sim seconds per wall second, changeable while it runs (fast_forward)
        self.pace = Pace(speed)
        self.instances: list[SimInstance] = []
        self.loop_stats = LoopStats()
        self._airframe_factory = airframe_factory
        self._defaults_factory = defaults_factory
        self._clock = clock
        # instance i keeps its signing key in <signing_dir>/<i>/mavlink/ (PX4: on its SD card)
        self.signing_dir = signing_dir
        self._task: asyncio.Task[None] | None = None

    async def start(self) -> None:
        try:
            for offset in range(self.count):
                self.instances.append(await self._open_instance(self.first_instance + offset))
        except BaseException:
            self.close()
            raise
        vehicles = [inst.vehicle for inst in self.instances]
        self._task = asyncio.create_task(
            run_vehicles(vehicles, self.pace, self.loop_stats, clock=self._clock),
            name="sim-vehicles",
        )

    @property
    def speed(self) -> float:
        """Sim seconds per wall second, now."""
        return self.pace.speed

    @contextlib.contextmanager
    def fast_forwarded(self, speed: float = FAST_FORWARD_SPEED) -> Iterator[None]:
        """The block at `speed` (a set-up flight nobody looks at), then the speed before."""
        before = self.pace.speed
        self.pace.set(speed)
        try:
            yield
        finally:
            self.pace.set(before)

    async def _open_instance(self, index: int) -> SimInstance:
        offset = index - self.first_instance
        vehicle = SimVehicle(
            self.airframe, sysid=index + 1,
            spawn_ned_m=(0.0, SPAWN_SPACING_M * offset, 0.0),
            airframe_factory=self._airframe_factory,
            defaults_factory=self._defaults_factory,
        )
        vehicle.ready_event = asyncio.Event()
        vehicle.wall_speed = lambda: self.pace.speed

        key_file = (self.signing_dir / str(index) / MAVLINK_SECRET_FILE
                    if self.signing_dir is not None else None)
        signing = VehicleSigning(key_file, sysid=vehicle.sysid, compid=vehicle.compid,
                                 is_armed=lambda: vehicle.armed)

        def port(base: int | None, local: bool) -> int | None:
            if base is None or base == 0:
                return 0 if local else None
            return base + offset

        api_link = await open_link(
            "api", vehicle.sysid, vehicle.compid, vehicle.handle_message, self.host,
            port(self.api_local_port, True) or 0, port(self.api_port, False),
            signing=signing, link_id=0,
        )
        try:
            gcs_local = port(self.gcs_local_port, True) or 0
            gcs_link = await open_link(
                "gcs", vehicle.sysid, vehicle.compid, vehicle.handle_message, self.host,
                gcs_local, self.gcs_port or None, signing=signing, link_id=1,
            )
        except BaseException:
            api_link.close()
            raise
        vehicle.attach_link(api_link, onboard=True)
        vehicle.attach_link(gcs_link, onboard=False)
        return SimInstance(index, vehicle.sysid, vehicle, api_link, gcs_link, signing)

    async def wait_ready(self, timeout_s: float | None = None) -> None:
        """Until every vehicle has a valid position and can arm (≈ 3 s sim time)."""
        waits = [inst.vehicle.ready_event.wait() for inst in self.instances
                 if inst.vehicle.ready_event is not None]
        await asyncio.wait_for(asyncio.gather(*waits), timeout_s)

    async def stop(self) -> None:
        task, self._task = self._task, None
        try:
            if task is not None:
                task.cancel()
                # its end, without taking on its cancellation; a crash of the loop still shows
                await asyncio.wait([task])
                if not task.cancelled() and (error := task.exception()) is not None:
                    raise error
        finally:
            self.close()

    def close(self) -> None:
        for inst in self.instances:
            inst.close()

    async def __aenter__(self) -> SimCluster:
        await self.start()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.stop()
