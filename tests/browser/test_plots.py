"""Plots in Chromium against `skyhelm serve` and its simulated quad: the uPlot charts start on
altitude and ground speed, any telemetry field of the state can be picked, and the picked
field's past 60 s shows at once and keeps growing, with the vehicle's values."""

from __future__ import annotations

from typing import Any

import httpx

from .flows import settle_vehicle
from .harness import vehicle_state

SERVE_ARGS = ["--sim-speed", "2"]
PAGE_TIMEOUT_MS = 20_000


def _points(page: Any, chart: int) -> int:
    points: int = page.evaluate("(i) => window.skyhelm.plots.charts[i].points()", chart)
    return points


def test_a_picked_field_is_plotted_live_with_the_vehicles_values(
    api: httpx.Client, page: Any
) -> None:
    settle_vehicle(api, flying=False)
    assert page.input_value("#plot-field-0") == "alt_above_home_m"
    assert page.input_value("#plot-field-1") == "ground_speed_m_s"
    page.wait_for_selector("#plot-0 canvas", timeout=PAGE_TIMEOUT_MS)
    page.wait_for_function("window.skyhelm.plots.charts[0].points() > 5", timeout=PAGE_TIMEOUT_MS)

    options = page.eval_on_selector_all("#plot-field-0 option", "os => os.map(o => o.value)")
    for field in ("attitude.roll_deg", "battery.voltage_v", "global.alt_amsl_m",
                  "message_ages_s.ATTITUDE"):  # fmt: skip
        assert field in options, field
    page.select_option("#plot-field-0", "battery.voltage_v")
    # the field's recent past is there at once, and new states add to it
    shown = _points(page, 0)
    assert shown > 5
    page.wait_for_function(
        f"window.skyhelm.plots.charts[0].points() > {shown}", timeout=PAGE_TIMEOUT_MS
    )
    latest = page.text_content("#plots .plot:first-child .plot-latest") or ""
    assert latest.endswith(" V"), latest
    voltage = vehicle_state(api)["battery"]["voltage_v"]
    plotted: list[float] = page.evaluate(
        "window.skyhelm.plots.charts[0].uplot.data[1].filter(Number.isFinite)"
    )
    assert abs(plotted[-1] - voltage) < 0.5, (plotted[-1], voltage)
    # the other chart keeps its own field
    assert page.input_value("#plot-field-1") == "ground_speed_m_s"
