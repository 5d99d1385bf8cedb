"""The README's Python client example flies and lands (its curl session flies in the chain
of documented flows, tests/client/test_flow_chain.py)."""

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
