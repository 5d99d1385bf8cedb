"""The parameter editor in Chromium against `skyhelm serve` with the simulated quad: every
parameter with the words, unit, range and default of the vehicle's component metadata; an
observer reads only; a value outside the range is refused in the metadata's words and never
sent; an edit is confirmed, the vehicle's echo shown, and the value marked as changed from
its default until it is put back (tests/px4/test_px4_params.py runs the same on PX4)."""

from __future__ import annotations

from typing import Any

import httpx

from .flows import settle_vehicle, take_control
from .param_editing import NAME, WORDS, pick, refuse_edit_and_reset


def test_every_parameter_with_its_metadata_and_observers_read_only(
    page: Any, api: httpx.Client
) -> None:
    settle_vehicle(api, flying=False)
    page.wait_for_selector(f"#param-row-{NAME}", timeout=30_000)
    count = len(api.get("/vehicles/1/params").json()["params"])
    assert (page.text_content("#params-summary") or "").startswith(f"{count} of {count}")
    pick(page, "horizontal vel")  # found by its description
    assert WORDS in (page.text_content("#params-detail") or "")
    page.select_option("#params-group", "Multicopter Position Control")
    page.fill("#params-search", "")
    rows = page.locator(".param-row").count()
    assert 5 < rows < count
    assert page.is_disabled("#param-set")  # not in control: read only
    assert page.is_disabled("#param-input")


def test_out_of_range_refused_in_the_metadata_words_and_an_edit_shows_as_changed(
    page: Any, api: httpx.Client
) -> None:
    settle_vehicle(api, flying=False)
    take_control(page)
    url = f"/vehicles/1/params/{NAME}"
    refuse_edit_and_reset(page, lambda: float(api.get(url).json()["value"]))


def test_a_value_set_elsewhere_shows_without_a_refresh(page: Any, api: httpx.Client) -> None:
    """A script sets the parameter the page shows: the vehicle's new value reaches the row and
    the detail at once (PX4 sends a changed parameter unasked), and the log says it."""
    settle_vehicle(api, flying=False)
    pick(page, NAME)
    assert page.text_content(f"#param-value-{NAME}") == "12.0 m/s"
    lease = api.post("/vehicles/1/control", json={"client_name": "script"}).json()["lease_id"]
    headers = {"X-Lease-Id": lease}
    try:
        answer = api.put(f"/vehicles/1/params/{NAME}", json={"value": 7}, headers=headers)
        assert answer.status_code == 200, answer.text
        page.wait_for_function(
            "([name]) => document.getElementById(`param-value-${name}`).textContent === '7.0 m/s'",
            arg=[NAME], timeout=10_000,
        )  # fmt: skip
        assert page.text_content("#param-detail-value") == "7.0 m/s"
        assert page.input_value("#param-input") == "7"
        assert "changed" in (page.get_attribute(f"#param-row-{NAME}", "class") or "")
        logged = page.evaluate(
            "Array.from(document.getElementById('log').children, (e) => e.textContent)"
        )
        assert any(line.endswith(f"params: {NAME} is now 7 (was 12)") for line in logged), logged
    finally:
        api.put(f"/vehicles/1/params/{NAME}", json={"value": 12}, headers=headers)
        api.delete("/vehicles/1/control", headers=headers)
    page.wait_for_function(
        "([name]) => document.getElementById(`param-value-${name}`).textContent === '12.0 m/s'",
        arg=[NAME], timeout=10_000,
    )  # fmt: skip
