"""The README's Python client example flies and lands; its curl session stops loudly when
its leg is not flown (the session itself flies in the chain of documented flows,
tests/client/test_flow_chain.py, after a flight that ended away from the origin)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import httpx

from tests.client.conftest import pilot_url
from tests.serve_process import Served

README = Path(__file__).resolve().parents[2] / "README.md"
URL_LINE = re.compile(r"^URL='[^']*'.*$", re.MULTILINE)


def readme_block(language: str, needle: str) -> str:
    """The README's first ```language block that contains needle."""
    for block in re.findall(rf"```{language}\n(.*?)```", README.read_text(), re.DOTALL):
        if needle in block:
            return str(block)
    raise AssertionError(f"README.md has no {language} block with {needle!r}")


def curl_session() -> str:
    return readme_block("sh", "URL='")


def test_the_readme_python_client_example_flies_and_lands(served: Served) -> None:
    example = readme_block("python", "SkyHelm(").replace(
        "http://127.0.0.1:8000/?token=Jq3...", pilot_url(served)
    )
    assert served.pilot_token in example
    result = subprocess.run(
        [sys.executable, "-c", example], capture_output=True, text=True, timeout=200, check=False
    )
    assert result.returncode == 0, result.stderr
    state = httpx.get(
        f"{served.base_url}/api/v1/vehicles/1",
        headers={"Authorization": f"Bearer {served.pilot_token}"},
    ).json()
    assert state["armed"] is False


def test_the_readme_session_fails_loudly_when_its_leg_is_not_flown(served: Served) -> None:
    """The same session with its leg's speed made 0 (and its wait for the leg 8 s): it stops
    at the leg with until_state's message and a non-zero exit, before the return and the
    "leg flown" line, and gives the lease back."""
    script = URL_LINE.sub(f"URL='{pilot_url(served)}'", curl_session())
    leg = '"north_m_s": 2, "east_m_s": 0'
    assert script.count(leg) == 1
    script = script.replace(leg, '"north_m_s": 0, "east_m_s": 0')
    wait = "$N0 + 10\" 60"
    assert script.count(wait) == 1
    script = script.replace(wait, "$N0 + 10\" 8")
    result = subprocess.run(
        ["bash", "-c", script], capture_output=True, text=True, timeout=200, check=False
    )
    assert result.returncode == 1, result.stdout[-2000:] + result.stderr[-2000:]
    assert "until_state: still not s['position_ned']['north_m'] >" in result.stderr
    assert "leg flown" not in result.stdout
    assert "MAV_CMD_NAV_RETURN_TO_LAUNCH" not in result.stdout
    control = httpx.get(
        f"{served.base_url}/api/v1/vehicles/1/control",
        headers={"Authorization": f"Bearer {served.pilot_token}"},
    ).json()
    assert control["holder"] is None  # the trap gave it back
