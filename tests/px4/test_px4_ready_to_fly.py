"""Ready to fly against real PX4 v1.16 SITL: the server runs first, PX4 boots after it, and
the state's arming_checks say "not ready" with PX4's own reasons from its arming-check report
until the checks pass, then "ready"."""

from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from tests.px4.conftest import MODEL, Px4Sitl, _stop, find_sitl
from tests.serve_process import Served, skyhelm_serve

pytestmark = pytest.mark.px4

BOOT_TIMEOUT_S = 90.0


@pytest.fixture(scope="module")
def booting_px4(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Px4Sitl, Served]]:
    """`skyhelm serve --connect` listening, then a fresh PX4 instance started."""
    sitl = find_sitl()
    log_dir = tmp_path_factory.mktemp("px4-ready")
    with skyhelm_serve(log_dir, "--connect", sitl.connect_url, "--no-scene") as served:
        started = subprocess.run(
            [str(sitl.sitl_dir / "run.sh"), str(sitl.instance), MODEL],
            env={**os.environ, "PX4_CLEAN": "1"}, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert started.returncode == 0, f"run.sh failed: {started.stdout}{started.stderr}"
        pid = int(started.stdout.strip().splitlines()[-1])
        try:
            yield sitl, served
        finally:
            _stop(pid)


def _arming_checks(http: httpx.Client, sysid: int) -> dict[str, Any] | None:
    answer = http.get(f"/vehicles/{sysid}")
    if answer.status_code == 404:
        return None  # not seen yet
    answer.raise_for_status()
    checks: dict[str, Any] | None = answer.json()["arming_checks"]
    return checks


def test_px4_not_ready_with_its_reasons_after_boot_then_ready(
    booting_px4: tuple[Px4Sitl, Served],
) -> None:
    sitl, served = booting_px4
    reports: list[dict[str, Any]] = []  # each new verdict from PX4's report, in order
    seen_s: list[float] = []  # when each came, in seconds since PX4 was launched
    headers = {"Authorization": f"Bearer {served.observer_token}"}
    with httpx.Client(base_url=served.api, headers=headers, timeout=10.0) as http:
        started_s = time.monotonic()
        deadline = started_s + BOOT_TIMEOUT_S
        while time.monotonic() < deadline:
            checks = _arming_checks(http, sitl.sysid)
            if checks is not None and (not reports or reports[-1] != checks):
                reports.append(checks)
                seen_s.append(time.monotonic() - started_s)
            if checks is not None and checks["source"] == "events" and checks["ready"]:
                break
            time.sleep(0.1)  # polling a real vehicle booting in real time
    for at_s, checks in zip(seen_s, reports, strict=True):  # with -s: what PX4 said, when
        print(f"{at_s:.1f} s", checks["source"], checks["ready"], checks["mode"],
              checks["can_arm_modes"])  # fmt: skip
        for reason in checks["reasons"] + checks["other_reasons"]:
            print("  ", reason["severity"], reason["text"], reason["component"], reason["modes"])
    reports = [c for c in reports if c["source"] == "events"]
    assert reports, "PX4's arming-check report never reached the state"
    assert reports[-1]["ready"] is True, f"never ready: {reports[-1]}"
    not_ready = [c for c in reports if c["ready"] is False]
    assert not_ready, "PX4 was ready from its first report"
    first = not_ready[0]
    errors = [r for r in first["reasons"] if r["severity"] in ("ERROR", "CRITICAL", "EMERGENCY")]
    assert errors, f"not ready without a failing check: {first}"
    # in PX4's words, from its events metadata (not an id or a placeholder)
    assert all(r["text"] and not r["text"].startswith("[unknown event") for r in errors), errors
    assert all(r["kind"] in ("arming_check", "health") for r in errors)
    assert all(first["mode"] in r["modes"] for r in errors)
    assert first["mode"] not in first["can_arm_modes"]
    assert reports[-1]["mode"] in reports[-1]["can_arm_modes"]
    assert not [r for r in reports[-1]["reasons"] if r["severity"] == "ERROR"]
