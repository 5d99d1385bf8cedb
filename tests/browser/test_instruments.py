"""The instruments in Chromium against `skyhelm serve` and its simulated quad: they show what
the vehicle reports (attitude, heading, altitude), a value greys out with its age when the
vehicle falls silent (the sim process paused) and comes back when it talks again, arming in
the air and killing the motors ask first, and no number reads "-0.0"."""

from __future__ import annotations

import re
from typing import Any

import httpx
import pytest

from .flows import click_and_wait_result, settle_vehicle, start_offboard_here, take_control
from .harness import Serve, altitude_m, vehicle_state, wait_for
from .pausing import sim_paused

SERVE_ARGS = ["--sim-speed", "2"]
PAGE_TIMEOUT_MS = 20_000


def _number(text: str) -> float:
    match = re.search(r"-?\d+(\.\d+)?", text)
    assert match, f"no number in {text!r}"
    return float(match.group())


def _adi(page: Any) -> tuple[float, float]:
    """Roll and pitch (deg) the attitude indicator draws, read back from its transform."""
    transform = page.get_attribute("#inst-attitude .adi-horizon", "transform") or ""
    match = re.fullmatch(r"rotate\((-?[\d.e-]+)\) translate\(0 (-?[\d.e-]+)\)", transform)
    assert match, transform
    return -float(match.group(1)), float(match.group(2)) / 2.2


def _angle_diff(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


@pytest.fixture
def flying(api: httpx.Client, page: Any) -> None:
    settle_vehicle(api, flying=True, altitude=6.0)


def test_instruments_show_the_vehicles_attitude_heading_and_altitude(
    api: httpx.Client, page: Any, flying: None
) -> None:
    page.wait_for_selector("#inst-attitude .adi-horizon[transform]", timeout=PAGE_TIMEOUT_MS)

    def agrees() -> bool:
        state = vehicle_state(api)
        roll, pitch = _adi(page)
        heading = _number(page.text_content("#inst-heading .tape-readout") or "")
        alt = _number(page.text_content("#inst-alt .inst-big") or "")
        return (
            abs(roll - state["attitude"]["roll_deg"]) < 2.0
            and abs(pitch - state["attitude"]["pitch_deg"]) < 2.0
            and _angle_diff(heading, state["heading_deg"]) < 3.0
            and abs(alt - altitude_m(state)) < 0.5
        )

    wait_for("the instruments to agree with the vehicle", agrees, 20.0, every_s=0.2)
    # hovering at 6 m: the altitude is the vehicle's, not a default
    assert _number(page.text_content("#inst-alt .inst-big") or "") > 4.5
    assert (page.text_content("#inst-alt .inst-big") or "").endswith(" m")
    gps = page.text_content("#inst-gps .inst-big")
    assert gps == "3D fix", gps
    assert page.text_content("#inst-ekf .inst-big") == "OK"
    assert page.is_hidden("#inst-vtol")  # a quad has no VTOL state
    battery = page.text_content("#inst-battery .inst-big") or ""
    assert battery.endswith(" %"), battery
    assert 0 < _number(battery) <= 100, battery
    assert "-0.0" not in (page.inner_text("body") or "")


def test_a_value_greys_out_with_its_age_while_the_vehicle_is_silent(
    api: httpx.Client, serve: Serve, page: Any
) -> None:
    settle_vehicle(api, flying=False)
    attitude = page.locator("#inst-attitude")
    page.wait_for_function(
        "document.getElementById('inst-attitude').dataset.age !== ''", timeout=PAGE_TIMEOUT_MS
    )
    assert "stale" not in (attitude.get_attribute("class") or "")
    with sim_paused(serve):
        page.wait_for_selector("#inst-attitude.stale", timeout=PAGE_TIMEOUT_MS)
        page.wait_for_selector("#t-att.stale", timeout=PAGE_TIMEOUT_MS)
        assert "grayscale(1)" in page.evaluate(
            "getComputedStyle(document.getElementById('inst-attitude')).filter"
        )
        first = _number(attitude.get_attribute("data-age") or "")
        # the age keeps growing on the page although no state comes
        page.wait_for_function(
            f"parseFloat(document.getElementById('inst-attitude').dataset.age) >= {first + 1.0}",
            timeout=PAGE_TIMEOUT_MS,
        )
        assert (attitude.get_attribute("data-age") or "").endswith(" s")
        assert "ATTITUDE" in (attitude.get_attribute("title") or "")
    page.wait_for_selector("#inst-attitude:not(.stale)", timeout=PAGE_TIMEOUT_MS)
    page.wait_for_selector("#t-att:not(.stale)", timeout=PAGE_TIMEOUT_MS)


# WCAG's contrast ratio of the dialog's title and text against its background
CONTRAST_IN_DIALOG = """() => {
    const rgb = (c) => c.match(/[\\d.]+/g).slice(0, 3).map(Number);
    const lum = (c) => {
        const [r, g, b] = rgb(c).map((v) => {
            v /= 255;
            return v <= 0.03928 ? v / 12.92 : ((v + 0.055) / 1.055) ** 2.4;
        });
        return 0.2126 * r + 0.7152 * g + 0.0722 * b;
    };
    const dialog = document.getElementById("confirm-dialog");
    const back = lum(getComputedStyle(dialog).backgroundColor);
    const ratio = (el) => {
        const [a, b] = [lum(getComputedStyle(el).color), back].sort((x, y) => y - x);
        return Math.round((a + 0.05) / (b + 0.05) * 10) / 10;
    };
    return { title: ratio(document.getElementById("confirm-title")),
             text: ratio(dialog.querySelector("p")) };
}"""


def _open_confirmation(page: Any, button: str) -> str:
    """Clicks a button that asks first; returns the title of the dialog it opened."""
    page.click(button)
    page.wait_for_selector("#confirm-dialog[open]", timeout=5_000)
    return page.text_content("#confirm-title") or ""


def _confirm_and_wait_result(page: Any, button: str, result_prefix: str) -> None:
    """Clicks the button, says yes in its dialog and waits for the answer in #result."""
    _open_confirmation(page, button)
    page.click("#confirm-ok")
    page.wait_for_function(
        "(prefix) => document.getElementById('result').textContent.startsWith(prefix)",
        arg=result_prefix,
        timeout=PAGE_TIMEOUT_MS,
    )


def test_arming_in_the_air_asks_first(api: httpx.Client, page: Any, flying: None) -> None:
    take_control(page)
    page.wait_for_function(
        "window.skyhelm.page.state && window.skyhelm.page.state.landed_state === 'IN_AIR'",
        timeout=PAGE_TIMEOUT_MS,
    )
    before = page.text_content("#result")
    assert _open_confirmation(page, "#btn-arm") == "Arm in the air?"
    page.click("#confirm-cancel")
    page.wait_for_selector("#confirm-dialog", state="hidden", timeout=5_000)
    assert page.text_content("#result") == before  # nothing was sent

    _confirm_and_wait_result(page, "#btn-arm", "Arm: ")
    assert vehicle_state(api)["armed"]


def test_kill_asks_first_then_disarms_at_once(api: httpx.Client, page: Any) -> None:
    settle_vehicle(api, flying=False)
    take_control(page)
    click_and_wait_result(page, "#btn-arm", confirm=True)
    wait_for("armed", lambda: vehicle_state(api)["armed"], 10.0)

    assert _open_confirmation(page, "#btn-kill") == "Kill the motors?"
    for scheme in ("dark", "light"):  # the question is read in either theme
        page.emulate_media(color_scheme=scheme)
        page.wait_for_function(f"document.documentElement.dataset.theme === '{scheme}'")
        ratios = page.evaluate(CONTRAST_IN_DIALOG)
        assert min(ratios.values()) >= 4.5, f"{scheme}: text contrast {ratios}"
    page.keyboard.press("Escape")
    page.wait_for_selector("#confirm-dialog", state="hidden", timeout=5_000)
    assert vehicle_state(api)["armed"]  # Escape is no

    _confirm_and_wait_result(page, "#btn-kill", "Kill: ACCEPTED")
    wait_for("disarmed", lambda: not vehicle_state(api)["armed"], 10.0)


def test_numbers_ages_and_battery_time_are_written_for_people(page: Any) -> None:
    """The page's own formatting and battery clock, run in the page's modules."""
    shown = page.evaluate("""async () => {
        const f = await import("./format.js");
        const { BatteryClock } = await import("./instruments.js");
        const clock = new BatteryClock();
        const byCurrent = clock.estimate(
            { remaining_pct: 50, current_a: 10, consumed_mah: 1000 }, 0);
        const rate = new BatteryClock();
        rate.estimate({ remaining_pct: 80 }, 0);
        const byRate = rate.estimate({ remaining_pct: 79 }, 30);
        const own = rate.estimate({ remaining_pct: 79, time_remaining_s: 615 }, 31);
        return {
            zero: [f.num(-0.04, 1), f.num(-0.0, 2), f.num(-0.06, 1), f.num(null), f.num(NaN)],
            units: [f.withUnit(12.345, "m"), f.withUnit(undefined, "m"), f.signed(1.25)],
            ages: [f.age(0.42), f.age(12.7), f.age(154.753), f.age(7300)],
            millis: [f.millis(17.4), f.millis(154753)],
            durations: [f.duration(45), f.duration(720), f.duration(3900), f.duration(35990),
                        f.duration(3590)],
            battery: [byCurrent, byRate, own],
            deadman: f.deadmanText({
                action: "brake", cause: "live_timeout", timeout_s: 0.5, ok: true,
                setpoint: { type: "position_ned", north_m: 10.04, east_m: -0.02, down_m: -5 },
            }),
            // the same brake while nothing came from the vehicle for 2.5 s: its silence
            vehicleSilent: f.deadmanText(
                { action: "brake", cause: "live_timeout", timeout_s: 0.5, ok: true },
                { vehicleSilentS: 2.5, vehicle: 1 }),
            vehicleTalking: f.deadmanText(
                { action: "brake", cause: "live_timeout", timeout_s: 0.5, ok: true },
                { vehicleSilentS: 0.05, vehicle: 1 }),
        };
    }""")
    assert shown["zero"] == ["0.0", "0.00", "-0.1", "–", "–"]
    assert shown["units"] == ["12.3 m", "–", "+1.3"]
    assert shown["ages"] == ["0.4 s", "12 s", "2 min 34 s", "2 h 01 min"]
    assert shown["millis"] == ["17 ms", "2 min 34 s"]
    # minutes rounded before they are split from the hours: never "9 h 60 min"
    assert shown["durations"] == ["45 s", "12 min", "1 h 05 min", "10 h 00 min", "1 h 00 min"]
    by_current, by_rate, own = shown["battery"]
    # 1000 mAh used for half the charge: 1000 mAh left at 10 A is 6 minutes
    assert by_current == {"seconds": pytest.approx(360.0), "how": "current"}
    # 1 % in 30 s with 79 % left
    assert by_rate == {"seconds": pytest.approx(79 * 30.0), "how": "rate"}
    assert own == {"seconds": 615, "how": "vehicle"}
    assert shown["deadman"] == (
        "deadman: brake (the pilot's live input fell silent for 0.5 s)"
        " — position ned north 10.0 east 0.0 down -5.0"
    )
    assert shown["vehicleSilent"] == (
        "deadman: brake (vehicle 1 went silent 2.5 s ago: the pilot's input could not reach it)"
    )
    assert (
        shown["vehicleTalking"] == "deadman: brake (the pilot's live input fell silent for 0.5 s)"
    )


def test_an_observer_sees_the_setpoint_flown_not_the_forms_defaults(
    api: httpx.Client, page: Any, second_page: Any, flying: None
) -> None:
    take_control(page)
    start_offboard_here(page, api)
    north = round(float(page.input_value("#sp-north_m")) + 3.0, 1)
    page.fill("#sp-north_m", str(north))  # the pilot moves the setpoint 3 m north
    wait_for(
        "the streamed setpoint 3 m further north",
        lambda: abs((vehicle_state(api)["setpoint"] or {}).get("north_m", 1e9) - north) < 0.05,
        10.0,
    )
    # the observer's panel shows what is flown, in the pilot's words and fields
    second_page.wait_for_function(
        "([n]) => Math.abs(parseFloat(document.getElementById('sp-north_m').value) - n) < 0.05",
        arg=[north],
        timeout=PAGE_TIMEOUT_MS,
    )
    flown = second_page.text_content("#sp-flown-text") or ""
    assert flown.startswith("Position · North "), flown
    assert abs(_number(flown.split("North ")[1]) - north) < 0.05, flown
    # the pilot's page shows the same, drawn by its own schedule (not at the observer's instant)
    page.wait_for_function(
        "([text]) => document.getElementById('sp-flown-text').textContent === text",
        arg=[flown], timeout=PAGE_TIMEOUT_MS,
    )
    assert second_page.is_disabled("#sp-north_m")  # observing: shown, not editable
