"""The parameter editor's steps, shared by the simulated vehicle's browser test and the one
against real PX4 SITL: MPC_XY_VEL_MAX (PX4: 0 … 20 m/s, default 12) refused outside its
range in the metadata's words, set to another value, shown as changed, put back to default."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

NAME = "MPC_XY_VEL_MAX"
WORDS = "Maximum horizontal velocity"


def pick(page: Any, search: str, name: str = NAME) -> None:
    """Search (the list draws its first rows only), then pick the parameter's row once the
    values have come (every parameter of PX4 takes a few seconds)."""
    page.fill("#params-search", search)
    page.wait_for_selector(f"#param-row-{name}", timeout=60_000)
    page.click(f"#param-row-{name}")
    page.wait_for_selector("#params-detail:not(.hidden)", timeout=5_000)


def wait_answer(page: Any, text: str) -> str:
    page.wait_for_function(
        "([text]) => document.getElementById('params-answer').textContent.includes(text)",
        arg=[text], timeout=20_000,
    )  # fmt: skip
    return page.text_content("#params-answer") or ""


def set_confirmed(page: Any, value: str) -> None:
    page.fill("#param-input", value)
    page.click("#param-set")
    page.locator("#confirm-dialog").wait_for(state="visible", timeout=5_000)
    assert WORDS in (page.text_content("#confirm-text") or "")
    page.click("#confirm-ok")


def refuse_edit_and_reset(page: Any, value_on_vehicle: Callable[[], float]) -> None:
    """On a page in control showing the vehicle: 1000 is refused and never sent, 8 is set
    and echoed and marked as changed, Default puts back 12 and the mark goes."""
    pick(page, NAME)
    assert page.text_content("#param-detail-range") == "0 … 20 m/s"
    assert page.text_content("#param-detail-default") == "12.0 m/s"
    before = value_on_vehicle()

    page.fill("#param-input", "1000")
    page.click("#param-set")
    text = wait_answer(page, "Not sent")
    assert f"{NAME}: 1000 is outside 0 … 20 m/s ({WORDS})" in text
    assert not page.locator("#confirm-dialog").is_visible()
    assert value_on_vehicle() == before

    new = 8.0 if before != 8.0 else 9.0
    set_confirmed(page, f"{new:g}")
    text = wait_answer(page, "echo")
    assert f"{NAME} = {new:.1f} m/s (the vehicle's echo), changed from the default" in text
    assert value_on_vehicle() == new
    assert page.text_content(f"#param-value-{NAME}") == f"{new:.1f} m/s"
    assert "changed" in (page.get_attribute(f"#param-row-{NAME}", "class") or "")
    assert page.text_content("#param-detail-changed") == "changed from the default"
    page.fill("#params-search", "")
    page.check("#params-changed-only")
    assert page.locator(f"#param-row-{NAME}").count() == 1

    page.click("#param-default")  # back to the default, confirmed again
    set_confirmed(page, page.input_value("#param-input"))
    wait_answer(page, f"{NAME} = 12.0 m/s")
    assert page.locator(f"#param-row-{NAME}").count() == 0  # "changed only" hides it now
    assert page.locator("#param-detail-changed").count() == 0
    page.uncheck("#params-changed-only")
    page.fill("#params-search", NAME)
    assert "changed" not in (page.get_attribute(f"#param-row-{NAME}", "class") or "")
    assert value_on_vehicle() == 12.0
