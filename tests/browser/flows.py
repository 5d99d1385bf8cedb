"""What a pilot does on the page, as steps the tests and the screenshot script share."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import httpx

from .harness import altitude_m, speed_m_s, vehicle_state, wait_for
from .pausing import fast_forward

RESULT_TIMEOUT_S = 30.0


# Software WebGL starts viser's client in ~8 CPU-s (5 s on a quiet machine, the page's main
# thread among them: the scene's frame is of the page's origin); a loaded machine gives the
# browser a fifth of a core or less, so a page with the scene takes a bound of its own.
SCENE_START_MS = 90_000


def open_dashboard(context: Any, url: str, scene: bool = True, init_script: str = "") -> Any:
    """Opens the page; without the scene, software WebGL leaves the CPU to the vehicle.
    ``init_script`` runs in the page before its own scripts."""
    page = context.new_page()
    if init_script:
        page.add_init_script(init_script)
    page.goto(url if scene else f"{url}&scene=off")
    page.wait_for_function("document.getElementById('mode').textContent !== '–'",
                           timeout=SCENE_START_MS if scene else 30_000)
    return page


def take_control(page: Any) -> None:
    page.click("#take-control")
    page.wait_for_selector("#release:not(.hidden)", timeout=10_000)
    page.wait_for_selector("#btn-arm:not([disabled])", timeout=10_000)
    page.wait_for_function(
        "document.getElementById('holder').textContent.startsWith('you')", timeout=10_000
    )


def wait_for_text(page: Any, element_id: str, text: str, *, starts: bool = False,
                  timeout_ms: float = 5_000) -> None:
    """Waits until the element's text contains ``text`` (begins with it: ``starts``)."""
    page.wait_for_function(
        "([id, text, starts]) => { const t = document.getElementById(id).textContent;"
        " return starts ? t.startsWith(text) : t.includes(text); }",
        arg=[element_id, text, starts], timeout=timeout_ms,
    )


def click_and_wait_result(
    page: Any, selector: str, expect: str = "ACCEPTED", confirm: bool = False
) -> str:
    """Clicks a command button and waits for the vehicle's answer to show in #result."""
    previous = page.text_content("#result")
    page.click(selector)
    if confirm:
        page.click(selector)
    page.wait_for_function(
        "([prev]) => { const r = document.getElementById('result');"
        " return !r.classList.contains('pending') && r.textContent !== prev; }",
        arg=[previous],
        timeout=RESULT_TIMEOUT_S * 1000,
    )
    text: str = page.text_content("#result") or ""
    assert expect in text, text
    return text


def arm_and_take_off(page: Any, api: httpx.Client, altitude: float) -> None:
    click_and_wait_result(page, "#btn-arm", confirm=True)
    page.fill("#takeoff-alt", str(altitude))
    click_and_wait_result(page, "#btn-takeoff")
    # up, and the take-off over (PX4 refuses some commands, a VTOL transition among them,
    # while it is still in TAKEOFF); the climb fast-forward, as the tests look at what follows
    with fast_forward(api):
        wait_for(
            f"altitude above {altitude - 0.8} m, out of TAKEOFF",
            lambda: altitude_m(s := vehicle_state(api)) > altitude - 0.8
            and s["mode"] != "TAKEOFF",
            60.0,
        )


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
        page.wait_for_timeout(30)  # not a wait: the pace of a hand's drag, step by step
    page.mouse.up()
    return float(slider.input_value())


def start_offboard_here(page: Any, api: httpx.Client) -> None:
    """OFFBOARD from the page, holding the current position."""
    page.select_option("#sp-type", "position")
    page.click("#sp-from-here")
    click_and_wait_result(page, "#btn-offboard-start")
    wait_for("OFFBOARD", lambda: vehicle_state(api)["mode"] == "OFFBOARD", 10.0)


def wait_position_hold(api: httpx.Client) -> dict[str, Any]:
    """Waits for a position setpoint with the vehicle stopped (after a brake); that state."""
    state: dict[str, Any] = wait_for(
        "a position hold with the vehicle stopped",
        lambda: (
            (s := vehicle_state(api))["setpoint"] is not None
            and s["setpoint"]["type"] == "position_ned"
            and speed_m_s(s) < 0.3
            and s
        ),
        15.0,
    )
    return state


class _RestPilot:
    """Takes the lease over REST (forced, from whoever holds it) to put the vehicle in a known
    state, renewing it on every poll, and gives it back afterwards."""

    def __init__(self, api: httpx.Client) -> None:
        self.api = api
        taken = api.post("/vehicles/1/control", json={"takeover": True, "force": True})
        taken.raise_for_status()
        self.headers = {"X-Lease-Id": taken.json()["lease_id"]}

    def command(self, path: str, body: dict[str, Any] | None = None) -> None:
        answer = self.api.post(f"/vehicles/1/{path}", json=body or {}, headers=self.headers)
        assert answer.status_code == 200, f"{path}: {answer.text}"

    def wait(self, what: str, check: Callable[[dict[str, Any]], bool], timeout_s: float) -> None:
        def renewed_state() -> bool:
            self.api.put("/vehicles/1/control", headers=self.headers)
            return check(vehicle_state(self.api))

        wait_for(what, renewed_state, timeout_s, every_s=0.1)

    def release(self) -> None:
        self.api.delete("/vehicles/1/control", headers=self.headers)


def _landed(state: dict[str, Any]) -> bool:
    return state["landed_state"] == "ON_GROUND" and not state["armed"]


def _hovering(state: dict[str, Any], altitude: float) -> bool:
    return (
        state["armed"] and state["landed_state"] == "IN_AIR" and altitude_m(state) > altitude - 0.8
    )


def settle_vehicle(api: httpx.Client, *, flying: bool, altitude: float = 5.0) -> None:
    """Put the vehicle in a known state whatever earlier tests left: nobody in control, no
    setpoint stream, and either disarmed on the ground or hovering in HOLD at least
    ``altitude`` - 0.8 m up. A vehicle already in that state is left where it is."""
    wait_for("the vehicle", lambda: api.get("/vehicles").json(), 30.0)
    state = vehicle_state(api)
    settled = _hovering(state, altitude) and state["mode"] == "HOLD" if flying else _landed(state)
    if settled and not state["stream"]["active"] and state["lease"]["holder"] is None:
        return
    pilot = _RestPilot(api)
    try:
        # a set-up flight: nothing looks at it, so the sim flies it fast-forward
        with fast_forward(api):
            if state["stream"]["active"] or state["mode"] == "OFFBOARD":
                pilot.command("offboard/stop", {"then_mode": "HOLD"})
            if flying and _hovering(vehicle_state(api), altitude):
                pilot.command("mode", {"mode": "HOLD"})
                return
            if not _landed(vehicle_state(api)):
                pilot.command("land")
                pilot.wait("landed and disarmed", _landed, 60.0)
            if flying:
                # PX4 never arms in LAND or RTL, where a landing leaves it, nor in a manual mode
                # (POSCTL) with no sticks coming: HOLD first, as a pilot does
                if vehicle_state(api)["mode"] != "HOLD":
                    pilot.command("mode", {"mode": "HOLD"})
                pilot.command("arm")
                pilot.command("takeoff", {"altitude_m": altitude})
                pilot.wait(
                    f"hovering at {altitude} m",
                    lambda s: _hovering(s, altitude) and s["mode"] == "HOLD",
                    60.0,
                )
    finally:
        pilot.release()
