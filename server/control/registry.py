"""The vehicles the server flies: every vehicle of every open link, by sysid, each with the
configured safety envelope and setpoint rate applied once when first seen."""

from __future__ import annotations

from dataclasses import replace

from server.link import Envelope, Link, Vehicle


class VehicleRegistry:
    def __init__(self, envelope: Envelope, stream_rate_hz: float) -> None:
        self._envelope = envelope
        self._stream_rate_hz = stream_rate_hz
        self._links: list[Link] = []
        self._configured: set[int] = set()

    @property
    def links(self) -> tuple[Link, ...]:
        return tuple(self._links)

    def add_link(self, link: Link) -> None:
        self._links.append(link)

    def remove_links(self) -> list[Link]:
        links, self._links = self._links, []
        return links

    def all(self) -> list[Vehicle]:
        """Vehicles by sysid; the first link that saw a sysid owns it."""
        seen: dict[int, Vehicle] = {}
        for link in self._links:
            for sysid, vehicle in link.vehicles.items():
                seen.setdefault(sysid, vehicle)
        for vehicle in seen.values():
            self._configure(vehicle)
        return [seen[sysid] for sysid in sorted(seen)]

    def get(self, vehicle_id: int) -> Vehicle | None:
        for link in self._links:
            vehicle = link.vehicles.get(vehicle_id)
            if vehicle is not None:
                self._configure(vehicle)
                return vehicle
        return None

    def _configure(self, vehicle: Vehicle) -> None:
        if id(vehicle) not in self._configured:
            self._configured.add(id(vehicle))
            vehicle.envelope = replace(self._envelope)
            vehicle.stream_rate_hz = self._stream_rate_hz
