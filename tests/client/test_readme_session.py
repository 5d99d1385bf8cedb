"""The README's curl session, pasted into bash as it stands (only the URL line replaced by
the live server's), flies with default control settings and ends landed and disarmed; its
Python client example does too."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import httpx
import pytest

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


@pytest.mark.skipif(shutil.which("curl") is None, reason="needs curl")
def test_the_readme_curl_session_flies_and_lands(served: Served) -> None:
    script = URL_LINE.sub(f"URL='{pilot_url(served)}'", curl_session(), count=1)
    assert served.pilot_token in script
    result = subprocess.run(
        ["bash", "-c", script], capture_output=True, text=True, timeout=200, check=False
    )
    assert result.returncode == 0, result.stderr
    assert '"result":"ACCEPTED"' in result.stdout  # arm, takeoff, offboard, rtl
    assert '"limit":12.0' in result.stdout  # the envelope's refusal, as shown
    state = httpx.get(
        f"{served.base_url}/api/v1/vehicles/1",
        headers={"Authorization": f"Bearer {served.pilot_token}"},
    ).json()
    assert state["armed"] is False
    assert state["landed_state"] == "ON_GROUND"
    assert state["position_ned"]["north_m"] == pytest.approx(0.0, abs=2.0)  # home again


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
