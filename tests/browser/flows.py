"""What a pilot does on the page, as steps the tests and the screenshot script share."""

from __future__ import annotations

from typing import Any

import httpx

from .harness import altitude_m, vehicle_state, wait_for

RESULT_TIMEOUT_S = 30.0


def open_dashboard(context: Any, url: str, scene: bool = True) -> Any:
    """Opens the page; without the scene, software WebGL leaves the CPU to the vehicle."""
    page = context.new_page()
    page.goto(url if scene else f"{url}&scene=off")
    page.wait_for_function(
        "document.getElementById('mode').textContent !== '–'", timeout=30_000
    )
    return page


def take_control(page: Any) -> None:
    page.click("#take-control")
    page.wait_for_selector("#release:not(.hidden)", timeout=10_000)
    page.wait_for_selector("#btn-arm:not([disabled])", timeout=10_000)
    page.wait_for_function("document.getElementById('holder').textContent.startsWith('you')",
                           timeout=10_000)


def click_and_wait_result(page: Any, selector: str, expect: str = "ACCEPTED",
                          confirm: bool = False) -> str:
    """Clicks a command button and waits for the vehicle's answer to show in #result."""
    previous = page.text_content("#result")
    page.click(selector)
    if confirm:
        page.click(selector)
    page.wait_for_function(
        "([prev]) => { const r = document.getElementById('result');"
        " return !r.classList.contains('pending') && r.textContent !== prev; }",
        arg=[previous], timeout=RESULT_TIMEOUT_S * 1000,
    )
    text: str = page.text_content("#result") or ""
    assert expect in text, text
    return text


def arm_and_take_off(page: Any, api: httpx.Client, altitude: float) -> None:
    click_and_wait_result(page, "#btn-arm", confirm=True)
    page.fill("#takeoff-alt", str(altitude))
    click_and_wait_result(page, "#btn-takeoff")
    wait_for(f"altitude above {altitude - 0.8} m",
             lambda: altitude_m(vehicle_state(api)) > altitude - 0.8, 60.0)


def drag_slider_to(page: Any, selector: str, value: float) -> float:
    """Drags a range input's thumb with the mouse to `value`; returns the value it took."""
    slider = page.locator(selector)
    box = slider.bounding_box()
    low = float(slider.get_attribute("min"))
    high = float(slider.get_attribute("max"))
    current = float(slider.input_value())

    def x_of(v: float) -> float:
        # Chromium's thumb travels the width minus its own width (≈ 16 px).
        thumb = 16.0
        return float(box["x"] + thumb / 2 + (v - low) / (high - low) * (box["width"] - thumb))

    y = box["y"] + box["height"] / 2
    page.mouse.move(x_of(current), y)
    page.mouse.down()
    steps = 12
    for i in range(1, steps + 1):
        page.mouse.move(x_of(current + (value - current) * i / steps), y)
        page.wait_for_timeout(30)
    page.mouse.up()
    return float(slider.input_value())
