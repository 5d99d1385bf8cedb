"""Parameters on real PX4 v1.16 SITL: the metadata PX4 serves (its parameters.json over
MAVLink FTP) describes MPC_XY_VEL_MAX as 0 … 20 m/s, default 12; the API refuses 1000 with
PX4's words unless forced; the page's editor refuses it too, sets another value, shows PX4's
echo and the value as changed from the default, and puts the default back."""

from __future__ import annotations

import subprocess
from collections.abc import Iterator

import httpx
import pytest

from tests.browser.flows import open_dashboard, take_control
from tests.browser.harness import chromium_context
from tests.browser.param_editing import NAME, WORDS, pick, refuse_edit_and_reset
from tests.px4.conftest import Px4Sitl
from tests.serve_process import Served
from tests.waiting import wait_for_blocking

pytestmark = pytest.mark.px4


@pytest.fixture(scope="module")
def http(px4: Px4Sitl, served_px4: Served) -> Iterator[httpx.Client]:
    auth = {"Authorization": f"Bearer {served_px4.pilot_token}"}
    with httpx.Client(base_url=served_px4.api, headers=auth, timeout=30.0) as client:
        wait_for_blocking(
            "PX4 listed",
            lambda: any(v["id"] == px4.sysid for v in client.get("/vehicles").json()),
            60.0, 0.5,
        )  # fmt: skip
        yield client


def test_px4_metadata_gives_the_range_and_the_api_refuses_outside_it(
    px4: Px4Sitl, http: httpx.Client
) -> None:
    vehicle = f"/vehicles/{px4.sysid}"
    metadata = http.get(f"{vehicle}/params/metadata").json()
    assert metadata["available"], metadata["error"]
    assert len(metadata["parameters"]) > 1000  # PX4 describes all of its parameters
    velocity = metadata["parameters"][NAME]
    assert (velocity["min"], velocity["max"], velocity["units"]) == (0.0, 20.0, "m/s")
    assert (velocity["default"], velocity["short_desc"]) == (12.0, WORDS)

    lease = http.post(f"{vehicle}/control", json={"client_name": "px4 params"})
    lease.raise_for_status()
    headers = {"X-Lease-Id": lease.json()["lease_id"]}
    url = f"{vehicle}/params/{NAME}"
    try:
        before = http.get(url).json()["value"]
        refused = http.put(url, json={"value": 1000}, headers=headers)
        assert refused.status_code == 422, refused.text
        assert f"1000 is outside 0 … 20 m/s ({WORDS})" in refused.json()["detail"]["reason"]
        assert http.get(url).json()["value"] == before
        # PX4 itself takes it: force is the caller's word that it means it
        forced = http.put(url, json={"value": 21.0, "force": True}, headers=headers)
        assert (forced.status_code, forced.json()["value"]) == (200, 21.0), forced.text
        back = http.put(url, json={"value": before}, headers=headers)
        assert back.json()["value"] == before
    finally:
        http.delete(f"{vehicle}/control", headers=headers)


def test_px4_editor_refuses_sets_and_shows_the_change_from_default(
    px4: Px4Sitl, served_px4: Served, http: httpx.Client
) -> None:
    url = f"/vehicles/{px4.sysid}/params/{NAME}"
    with chromium_context() as context:
        dashboard = f"{served_px4.base_url}/?token={served_px4.pilot_token}"
        page = open_dashboard(context, dashboard, scene=False)
        take_control(page)
        refuse_edit_and_reset(page, lambda: float(http.get(url).json()["value"]))


def _px4_shell_sets(px4: Px4Sitl, value: float) -> None:
    """`param set` in the instance's own shell, as someone at the vehicle would."""
    shell = px4.sitl_dir / "build" / "px4_sitl_default" / "bin" / "px4-param"
    subprocess.run([str(shell), "--instance", str(px4.instance), "set", NAME, f"{value:g}"],
                   check=True, capture_output=True, timeout=10)  # fmt: skip


def test_px4_a_value_set_in_its_shell_shows_in_the_editor(
    px4: Px4Sitl, served_px4: Served, http: httpx.Client
) -> None:
    """PX4 sends a parameter changed on board unasked: the page's editor, which read 12
    before, shows 9 without a refresh, then 12 again."""
    url = f"/vehicles/{px4.sysid}/params/{NAME}"
    with chromium_context() as context:
        page = open_dashboard(context, f"{served_px4.base_url}/?token={served_px4.pilot_token}",
                              scene=False)  # fmt: skip
        pick(page, NAME)
        before = float(http.get(url).json()["value"])
        new = 9.0 if before != 9.0 else 10.0
        try:
            _px4_shell_sets(px4, new)
            page.wait_for_function(
                "([name, text]) => document.getElementById(`param-value-${name}`).textContent"
                " === text", arg=[NAME, f"{new:.1f} m/s"], timeout=10_000,
            )  # fmt: skip
            assert page.text_content("#param-detail-value") == f"{new:.1f} m/s"
        finally:
            _px4_shell_sets(px4, before)
        page.wait_for_function(
            "([name, text]) => document.getElementById(`param-value-${name}`).textContent"
            " === text", arg=[NAME, f"{before:.1f} m/s"], timeout=10_000,
        )  # fmt: skip
