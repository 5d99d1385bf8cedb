"""The page of a fleet server: two edges (each `skyhelm serve --zenoh` with its simulated
vehicle) and a fleet server (`skyhelm serve --fleet`) as separate processes, meeting over
Zenoh on loopback. The fleet panel lists both vehicles with their freshness and controller,
the map draws both, a vehicle of an edge is flown from the page through the fleet server
(take control, arm, takeoff, fly to a map point, land), an observer cannot fly, and an edge
that dies shows LOST until it is back."""

from __future__ import annotations

import os
import secrets
import signal
import socket
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import httpx
import pytest

from .flows import click_and_wait_result, take_control
from .harness import Serve, altitude_m, vehicle_state, wait_for

FLEET = f"browser{secrets.token_hex(3)}"
OBSERVER = secrets.token_urlsafe(16)
ZENOH_LOOPBACK = ["--fleet-name", FLEET, "--no-zenoh-multicast-scouting", "--no-scene",
                  f"--observer-token={OBSERVER}"]


@dataclass
class Fleet:
    server: Serve
    edges: dict[str, Serve]


def _free_endpoint() -> str:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{probe.getsockname()[1]}"


@pytest.fixture(scope="module")
def fleet() -> Iterator[Fleet]:
    token = secrets.token_urlsafe(16)
    endpoint = _free_endpoint()
    server = Serve(token=token, extra_args=["--fleet", "--zenoh-listen", endpoint,
                                            *ZENOH_LOOPBACK])
    edges = {
        name: Serve(token=token, extra_args=[
            "--zenoh", "--edge-name", name, "--zenoh-listen", "tcp/127.0.0.1:0",
            "--zenoh-connect", endpoint, *ZENOH_LOOPBACK,
        ])
        for name in ("edge-a", "edge-b")
    }
    started: list[Serve] = []
    try:
        for process in (server, *edges.values()):
            process.start()
            started.append(process)
        yield Fleet(server, edges)
    finally:
        for process in reversed(started):
            process.stop()
            process.discard_log()


@pytest.fixture(scope="module")
def serve(fleet: Fleet) -> Serve:
    """The page under test is the fleet server's (conftest's `page` opens it)."""
    return fleet.server


def _rows(page: Any) -> dict[str, dict[str, str]]:
    rows: dict[str, dict[str, str]] = page.evaluate(
        """() => Object.fromEntries([...document.querySelectorAll('#fleet-table tbody tr')]
            .map((r) => [r.dataset.key, {alive: r.dataset.alive, age: r.dataset.ageS,
              cls: r.className, text: r.innerText}]))"""
    )
    return rows


def _both_listed(page: Any) -> bool:
    """Both vehicles alive with a state (presence may come first)."""
    rows = _rows(page)
    return all(rows.get(k, {}).get("alive") == "true" and rows[k]["age"]
               for k in ("edge-a/1", "edge-b/1"))


def test_the_panel_lists_every_edges_vehicle_fresh_and_the_map_draws_them(page: Any) -> None:
    wait_for("both edges' vehicles alive in the panel", lambda: _both_listed(page), 60.0)
    rows = _rows(page)
    for key in ("edge-a/1", "edge-b/1"):
        assert float(rows[key]["age"]) < 2.0, rows[key]
        assert "stale" not in rows[key]["cls"]
        assert "nobody" in rows[key]["text"]
        assert "disarmed" in rows[key]["text"]
    page.wait_for_function("document.querySelectorAll('.map-vehicle').length === 2",
                           timeout=30_000)
    labels = page.locator(".map-vehicle .map-vehicle-id").all_text_contents()
    assert sorted(labels) == ["edge-a/1", "edge-b/1"]
    # nothing local on a fleet server: the first fleet vehicle is shown
    assert page.evaluate("window.skyhelm.page.vehicleId") in ("edge-a/1", "edge-b/1")


def test_a_vehicle_of_an_edge_is_flown_from_the_page(page: Any, fleet: Fleet) -> None:
    wait_for("both listed", lambda: _both_listed(page), 60.0)
    with fleet.edges["edge-b"].client() as edge_b, fleet.edges["edge-a"].client() as edge_a:
        page.click("#fleet-table tr[data-key='edge-b/1']")
        page.wait_for_function("window.skyhelm.page.state?.vehicle === 'edge-b/1'",
                               timeout=10_000)
        take_control(page)
        # the edge holds the lease, named after this tab, and the panel says it is ours
        holder = edge_b.get("/vehicles/1/control").json()["holder"]
        assert holder.startswith("pilot · ")
        assert "tab" in holder
        page.wait_for_function(
            "document.querySelector(\"tr[data-key='edge-b/1'] .fleet-control\")"
            ".textContent === 'you'", timeout=10_000)
        wait_for("edge-b ready to arm", lambda: vehicle_state(edge_b)["ready_to_arm"], 60.0)
        click_and_wait_result(page, "#btn-arm", confirm=True)
        page.fill("#takeoff-alt", "3")
        click_and_wait_result(page, "#btn-takeoff")
        wait_for("edge-b above 2.2 m", lambda: altitude_m(vehicle_state(edge_b)) > 2.2, 60.0)
        assert not vehicle_state(edge_a)["armed"], "only the selected edge's vehicle flies"
        page.wait_for_function(
            "document.querySelector(\"tr[data-key='edge-b/1'] .fleet-armed\")"
            ".textContent === 'ARMED'", timeout=10_000)

        # fly to a map point 8 m north of where it is
        start = vehicle_state(edge_b)
        page.evaluate(
            """([lat, lon]) => window.skyhelm.map.offerGoto({lat: lat + 8 / 111_200, lng: lon})""",
            [start["global"]["lat_deg"], start["global"]["lon_deg"]],
        )
        page.fill("#map-goto-alt", "3")
        page.click("#map-goto-go")
        wait_for("edge-b 5 m further north",
                 lambda: vehicle_state(edge_b)["position_ned"]["north_m"]
                 > start["position_ned"]["north_m"] + 5.0, 60.0)

        click_and_wait_result(page, "#btn-land")
        wait_for("edge-b landed and disarmed", lambda: not vehicle_state(edge_b)["armed"], 90.0)
        page.click("#release")
        wait_for("the lease released at the edge",
                 lambda: edge_b.get("/vehicles/1/control").json()["holder"] is None, 15.0)


def test_an_observer_sees_the_fleet_and_cannot_fly(browser: Any, fleet: Fleet) -> None:
    url = fleet.server.url.replace(fleet.server.token, OBSERVER)
    observer = browser.new_page()
    try:
        observer.goto(f"{url}&scene=off")
        wait_for("the fleet listed to the observer", lambda: _both_listed(observer), 60.0)
        observer.click("#fleet-table tr[data-key='edge-a/1']")
        observer.click("#take-control")
        observer.wait_for_function(
            "[...document.querySelectorAll('#log div')].some((d) =>"
            " d.textContent.includes('control refused'))", timeout=15_000)
        assert observer.evaluate("window.skyhelm.page.control") is None
        with httpx.Client(base_url=f"{fleet.edges['edge-a'].base}/api/v1", timeout=10.0,
                          headers={"Authorization": f"Bearer {fleet.server.token}"}) as edge_a:
            assert edge_a.get("/vehicles/1/control").json()["holder"] is None
    finally:
        observer.close()


def test_an_edge_that_dies_shows_lost_and_comes_back(page: Any, fleet: Fleet) -> None:
    wait_for("both listed", lambda: _both_listed(page), 60.0)
    edge_a = fleet.edges["edge-a"]
    process = edge_a._process
    assert process is not None
    # killed with its simulated vehicle (its process group), no goodbye: only Zenoh's
    # liveliness can tell
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    wait_for("edge-a/1 LOST in the panel",
             lambda: _rows(page)["edge-a/1"]["alive"] == "false", 15.0)
    row = _rows(page)["edge-a/1"]
    assert "LOST" in row["text"]
    assert "lost" in row["cls"]
    assert _rows(page)["edge-b/1"]["alive"] == "true"
    edge_a.restart()
    wait_for("edge-a/1 back", lambda: _rows(page)["edge-a/1"]["alive"] == "true", 90.0)
    wait_for("edge-a/1 fresh again", lambda: float(_rows(page)["edge-a/1"]["age"]) < 2.0, 30.0)
