"""A vehicle heard only after the page opened (an autopilot powered after the ground
station): the page shows it as soon as the server lists it, its first state drawn within
100 ms of arriving at the page's socket, and a fresh one (not states from seconds ago)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from .harness import Serve
from .test_control_after_restart import SimulatedVehicle
from .test_page_draws import DRAWN_WITHIN_MS, PAGE_TIMEOUT_MS, STATE_ARRIVALS

# The vehicle listed at the page, then its socket opened and its first state sent: the
# server's part, on its own loop (a backoff after a refused socket would take seconds).
SHOWN_AFTER_LISTED_MS = 1000.0

LISTED_ARRIVALS = """
window.__listed = null;
const ListedSocket = window.WebSocket;
window.WebSocket = class extends ListedSocket {
  constructor(url, ...rest) {
    super(url, ...rest);
    if (!String(url).includes("/ws/telemetry")) return;
    this.addEventListener("message", (event) => {
      const message = JSON.parse(event.data);
      if (message.type === "vehicles" && message.vehicles.length && window.__listed === null) {
        window.__listed = performance.now();
      }
    });
  }
};
"""


@pytest.fixture(scope="module")
def vehicle() -> Iterator[SimulatedVehicle]:
    sim = SimulatedVehicle()
    sim.silence()  # not heard until the page is open
    try:
        yield sim
    finally:
        sim.stop()


@pytest.fixture(scope="module")
def serve(vehicle: SimulatedVehicle) -> Iterator[Serve]:
    with Serve(extra_args=["--connect", f"udpout:127.0.0.1:{vehicle.port}"]).running() as server:
        yield server


def test_a_vehicle_that_joins_after_the_page_opened_is_drawn_at_once(
    serve: Serve, vehicle: SimulatedVehicle, browser: Any
) -> None:
    page = browser.new_page()
    page.add_init_script(STATE_ARRIVALS)
    page.add_init_script(LISTED_ARRIVALS)
    try:
        page.goto(f"{serve.url}&scene=off")
        page.wait_for_function(
            "document.getElementById('log').textContent.includes('dashboard ready')",
            timeout=PAGE_TIMEOUT_MS,
        )
        assert page.text_content("#mode") == "–"  # no vehicle yet
        vehicle.resume()
        page.wait_for_function("window.skyhelm.draws.state >= 1 && window.__arrivals.length >= 1",
                               timeout=PAGE_TIMEOUT_MS)
        listed: float = page.evaluate("window.__listed")
        first_arrival: float = page.evaluate("window.__arrivals[0]")
        first_drawn: float = page.evaluate("window.skyhelm.drawTimes.state[0]")
        assert first_drawn >= first_arrival
        assert first_drawn - first_arrival <= DRAWN_WITHIN_MS
        assert first_drawn - listed <= SHOWN_AFTER_LISTED_MS
        # what is drawn is the vehicle now: its link on time, not a state from seconds ago
        assert page.text_content("#mode") != "–"
        assert page.text_content("#link-health") == "< 1 s"
    finally:
        page.close()
