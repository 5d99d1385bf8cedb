"""The parameter editor in Chromium against `skyhelm serve` with the simulated quad: every
parameter with the words, unit, range and default of the vehicle's component metadata; an
observer reads only; a value outside the range is refused in the metadata's words and never
sent; an edit is confirmed, the vehicle's echo shown, and the value marked as changed from
its default until it is put back."""

from __future__ import annotations

from typing import Any

import httpx

from .flows import settle_vehicle, take_control

NAME = "MPC_XY_VEL_MAX"
URL = f"/vehicles/1/params/{NAME}"


def _pick(page: Any, search: str, name: str) -> None:
    page.fill("#params-search", search)
    page.click(f"#param-row-{name}")
    page.wait_for_selector("#params-detail:not(.hidden)", timeout=5_000)


def _answer(page: Any, text: str) -> str:
    page.wait_for_function(
        "([text]) => document.getElementById('params-answer').textContent.includes(text)",
        arg=[text], timeout=20_000,
    )  # fmt: skip
    return page.text_content("#params-answer") or ""


def _set_confirmed(page: Any, value: str) -> None:
    page.fill("#param-input", value)
    page.click("#param-set")
    dialog = page.locator("#confirm-dialog")
    dialog.wait_for(state="visible", timeout=5_000)
    assert "Maximum horizontal velocity" in (page.text_content("#confirm-text") or "")
    page.click("#confirm-ok")


def test_every_parameter_with_its_metadata_and_observers_read_only(
    page: Any, api: httpx.Client
) -> None:
    settle_vehicle(api, flying=False)
    page.wait_for_selector(f"#param-row-{NAME}", timeout=30_000)
    count = len(api.get("/vehicles/1/params").json()["params"])
    assert (page.text_content("#params-summary") or "").startswith(f"{count} of {count}")
    _pick(page, "horizontal vel", NAME)  # found by its description
    assert "Maximum horizontal velocity" in (page.text_content("#params-detail") or "")
    assert page.text_content("#param-detail-range") == "0 … 20 m/s"
    assert page.text_content("#param-detail-default") == "12.0 m/s"
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
    page.wait_for_selector(f"#param-row-{NAME}", timeout=30_000)
    _pick(page, NAME, NAME)
    assert not page.is_disabled("#param-set")
    assert api.get(URL).json()["value"] == 12.0

    page.fill("#param-input", "1000")
    page.click("#param-set")
    text = _answer(page, "Not sent")
    assert "1000 is outside 0 … 20 m/s (Maximum horizontal velocity)" in text
    assert not page.locator("#confirm-dialog").is_visible()
    assert api.get(URL).json()["value"] == 12.0

    _set_confirmed(page, "8")
    text = _answer(page, "echo")
    assert f"{NAME} = 8.0 m/s (the vehicle's echo), changed from the default" in text
    assert api.get(URL).json()["value"] == 8.0
    assert page.text_content(f"#param-value-{NAME}") == "8.0 m/s"
    assert "changed" in (page.get_attribute(f"#param-row-{NAME}", "class") or "")
    assert page.text_content("#param-detail-changed") == "changed from the default"
    page.fill("#params-search", "")
    page.check("#params-changed-only")
    assert page.locator(f"#param-row-{NAME}").count() == 1

    page.click("#param-default")  # back to the default, confirmed again
    _set_confirmed(page, page.input_value("#param-input"))
    _answer(page, f"{NAME} = 12.0 m/s")
    assert page.locator(f"#param-row-{NAME}").count() == 0  # "changed only" hides it now
    assert page.locator("#param-detail-changed").count() == 0
    page.uncheck("#params-changed-only")
    assert "changed" not in (page.get_attribute(f"#param-row-{NAME}", "class") or "")
    assert api.get(URL).json()["value"] == 12.0
