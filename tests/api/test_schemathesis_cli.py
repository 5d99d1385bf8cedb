"""The schemathesis command as a user runs it, against a live `skyhelm serve` with its
simulated quad: the phases the in-process run of tests/api/test_openapi_fuzz.py leaves out
(examples, coverage of every bound and the stateful links), with every check. No failure, and
no traceback in the server's log. tests/api/schemathesis.toml is that run's configuration."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import httpx
import pytest

from tests.serve_process import skyhelm_serve

CLI_CONFIG = Path(__file__).with_name("schemathesis.toml")
CLI_EXAMPLES = 10
# 100-140 s on a quiet machine of 2 cores; beside two busy loops more than 400 s
CLI_TIMEOUT_S = 900.0
# the answer a call may take: a takeover ask waits for the holder (takeover_ask_s)
RESPONSE_TIME_S = 30


# the run's own bound, not the suite's 240 s
@pytest.mark.timeout(CLI_TIMEOUT_S + 60)
def test_schemathesis_every_phase_and_check_against_skyhelm_serve(tmp_path: Path) -> None:
    unlimited = ["--lockout-free-failures", "10000", "--control-rate-per-s", "100000",
                 "--control-burst", "100000"]  # fmt: skip
    with skyhelm_serve(tmp_path, "--no-scene", *unlimited) as served:
        # the server builds its OpenAPI document at the first request and keeps it; a server
        # just started beside busy jobs took longer than schemathesis waits for it (10 s)
        assert httpx.get(f"{served.base_url}/openapi.json", timeout=120.0).status_code == 200
        schemathesis = Path(sys.executable).with_name("schemathesis")
        command = [
            str(schemathesis), "--config-file", str(CLI_CONFIG), "--no-color", "run",
            f"{served.base_url}/openapi.json", "--checks", "all",
            "--phases", "examples,coverage,stateful", "-n", str(CLI_EXAMPLES),
            "-H", f"Authorization: Bearer {served.pilot_token}",
            "--max-response-time", str(RESPONSE_TIME_S),
            "--request-timeout", str(RESPONSE_TIME_S + 5), "--seed", "31",
        ]  # fmt: skip
        run = subprocess.run(
            command, capture_output=True, text=True, timeout=CLI_TIMEOUT_S, check=False,
            cwd=tmp_path,
        )  # fmt: skip
        log = served.stderr_path.read_text()
    report = run.stdout + run.stderr
    assert run.returncode == 0, report[-6000:]
    summary = report.split("SUMMARY")[-1]
    assert " passed" in summary, report[-3000:]
    assert "failure" not in summary, report[-3000:]
    assert "Traceback" not in log, log[-6000:]
