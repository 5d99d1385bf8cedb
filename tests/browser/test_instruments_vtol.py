"""The VTOL instrument in Chromium against `skyhelm serve` with the simulated standard VTOL:
shown only for a VTOL, with the state the vehicle reports (a quad's page hides it:
test_instruments)."""

from __future__ import annotations

from typing import Any

import httpx

from .harness import vehicle_state, wait_for

SERVE_ARGS = ["--sim-airframe", "vtol", "--sim-speed", "2"]


def test_a_vtol_shows_its_vtol_state(page: Any, api: httpx.Client) -> None:
    wait_for("the VTOL state", lambda: vehicle_state(api)["vtol_state"] == "MC", 30.0)
    page.wait_for_selector("#inst-vtol:not(.hidden)", timeout=20_000)
    page.wait_for_function(
        "document.querySelector('#inst-vtol .inst-big').textContent === 'Multicopter'",
        timeout=20_000,
    )
    assert "good" in (page.get_attribute("#inst-vtol", "class") or "")
    # airspeed is a VTOL pilot's number: shown with its unit
    assert (page.text_content("#inst-airspeed .inst-big") or "").endswith(" m/s")
