"""The Python client installs alone: into a fresh venv, from its one path (clients/python,
the wire format inside it, as its README says), pip asks an index for no skyhelm-* name, it
brings none of the server's dependencies, importing it loads nothing of the server or the
sim, and examples/fly_square.py flies the square with that venv's python against a served
simulated quad."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import venv
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.client.conftest import pilot_url
from tests.serve_process import Served

ROOT = Path(__file__).resolve().parents[2]
# what the server needs and a script author who installs the client must not get
SERVER_ONLY = {
    "fastapi", "starlette", "uvicorn", "pymavlink", "numpy", "pymap3d", "viser",
    "eclipse-zenoh",
}  # fmt: skip
INSTALL_TIMEOUT_S = 240.0
FLIGHT_TIMEOUT_S = 200.0

_LIST_DISTRIBUTIONS = (
    "import importlib.metadata as m, json; "
    "print(json.dumps(sorted({d.metadata['Name'].lower() for d in m.distributions()})))"
)
_IMPORT_CLIENT = (
    "import json, sys; import skyhelm_client; "
    "print(json.dumps({'file': skyhelm_client.__file__, 'modules': sorted(sys.modules)}))"
)


class Standalone:
    """A fresh venv with the client being installed into it (pip runs while the server
    starts)."""

    def __init__(self, directory: Path) -> None:
        venv.create(directory, with_pip=False)
        self.python = directory / "bin" / "python"
        self.log = directory / "pip.log"
        command = [sys.executable, "-m", "pip", "--python", str(self.python), "install"]
        command += ["--disable-pip-version-check", "--no-input", "--no-compile"]
        command += [str(ROOT / "clients" / "python")]
        with self.log.open("w") as log:
            self._pip = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env=_env())

    def installed(self) -> None:
        code = self._pip.wait(timeout=INSTALL_TIMEOUT_S)
        assert code == 0, f"pip install failed: {self.log.read_text()[-3000:]}"

    def run(self, *args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [str(self.python), *args],
            capture_output=True,
            text=True,
            timeout=timeout_s,
            check=False,
            cwd=self.python.parent.parent,
            env=_env(),
        )

    def stop(self) -> None:
        if self._pip.poll() is None:
            self._pip.kill()
            self._pip.wait()


def _env() -> dict[str, str]:
    """This environment without what would let the venv see the repository's code."""
    return {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH",)}


@pytest.fixture
def standalone(tmp_path: Path) -> Iterator[Standalone]:
    installing = Standalone(tmp_path / "client-venv")
    try:
        yield installing
    finally:
        installing.stop()


def test_the_client_installs_alone_and_flies_the_square(
    standalone: Standalone, served: Served
) -> None:
    standalone.installed()

    listed = standalone.run("-c", _LIST_DISTRIBUTIONS)
    assert listed.returncode == 0, listed.stderr
    distributions = set(json.loads(listed.stdout))
    assert {"skyhelm-client", "httpx", "pydantic"} <= distributions
    assert not distributions & SERVER_ONLY, distributions & SERVER_ONLY
    assert {name for name in distributions if name.startswith("skyhelm")} == {"skyhelm-client"}

    imported = standalone.run("-c", _IMPORT_CLIENT + "; import skyhelm_wire.state")
    assert imported.returncode == 0, imported.stderr
    loaded = json.loads(imported.stdout)
    assert Path(loaded["file"]).is_relative_to(standalone.python.parent.parent)
    top_level = {name.split(".")[0] for name in loaded["modules"]}
    assert not top_level & {"server", "sim"}, sorted(top_level & {"server", "sim"})

    flight = standalone.run(
        str(ROOT / "examples" / "fly_square.py"), pilot_url(served), timeout_s=FLIGHT_TIMEOUT_S
    )
    output = flight.stdout + flight.stderr
    assert flight.returncode == 0, output[-3000:]
    assert output.count("at north") == 4, output[-3000:]
    assert "landed" in output


def test_pip_asks_no_index_for_a_skyhelm_name(tmp_path: Path) -> None:
    """What ``pip install ./clients/python`` would fetch, resolved as for an empty venv:
    the client from its path and third-party projects only; no index is asked for a
    skyhelm-* page (a name we do not own there)."""
    report = tmp_path / "report.json"
    command = [sys.executable, "-m", "pip", "install", "--dry-run", "--ignore-installed",
               "--disable-pip-version-check", "--no-input", "-v", "--report", str(report),
               str(ROOT / "clients" / "python")]  # fmt: skip
    resolved = subprocess.run(
        command, capture_output=True, text=True, timeout=INSTALL_TIMEOUT_S, check=False,
        env=_env(),
    )  # fmt: skip
    assert resolved.returncode == 0, resolved.stderr[-3000:]
    installs = json.loads(report.read_text())["install"]
    ours = [item for item in installs if item["metadata"]["name"].lower().startswith("skyhelm")]
    assert [item["metadata"]["name"] for item in ours] == ["skyhelm-client"]
    assert ours[0]["is_direct"]
    assert ours[0]["download_info"]["url"] == (ROOT / "clients" / "python").as_uri()
    assert {"httpx", "websockets", "pydantic"} <= {
        item["metadata"]["name"].lower() for item in installs}  # fmt: skip
    # pip -v names every project page it reads (or fails to): none of ours
    log = resolved.stdout + resolved.stderr
    pages = [line for line in log.splitlines() if "skyhelm" in line.lower()
             and ("/simple/" in line or "project page" in line.lower())]  # fmt: skip
    assert not pages, pages
