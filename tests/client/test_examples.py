"""The examples fly their square against a live server, importing nothing beyond the
package's runtime dependencies (what `make run` installs)."""

from __future__ import annotations

import importlib.metadata
import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from tests.client.conftest import pilot_url
from tests.serve_process import Served

ROOT = Path(__file__).resolve().parents[2]

# Runs an example as `python examples/x.py URL` would, with every module of a distribution
# outside the runtime dependencies hidden, as in the environment `make run` creates.
_RUNNER = """
import json, runpy, sys
path, hidden = sys.argv[1], set(json.loads(sys.argv[2]))
sys.argv = [path, *sys.argv[3:]]

class Hidden:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in hidden:
            raise ModuleNotFoundError(f"No module named {name!r} (not installed by make run)")
        return None

sys.meta_path.insert(0, Hidden())
runpy.run_path(path, run_name="__main__")
"""


def _normalised(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def runtime_distributions() -> set[str]:
    """The distributions `pip install .` brings: pyproject's [project] dependencies and,
    recursively, theirs (extras left out)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    found = {_normalised(project["name"])}
    todo = [Requirement(text) for text in project["dependencies"]]
    while todo:
        requirement = todo.pop()
        name = _normalised(requirement.name)
        if name in found:
            continue
        if requirement.marker is not None and not requirement.marker.evaluate({"extra": ""}):
            continue
        found.add(name)
        try:
            todo += [Requirement(text) for text in importlib.metadata.requires(name) or []]
        except importlib.metadata.PackageNotFoundError:
            continue
    return found


def modules_not_installed_by_make_run() -> set[str]:
    """Top-level modules installed here that `pip install .` would not bring."""
    runtime = runtime_distributions()
    return {
        module
        for module, owners in importlib.metadata.packages_distributions().items()
        if not any(_normalised(owner) in runtime for owner in owners)
    }


@pytest.mark.parametrize("example", ["fly_square.py", "fly_square_async.py"])
def test_example_flies_the_square_on_runtime_dependencies(
    served: Served, example: str, tmp_path: Path
) -> None:
    hidden = modules_not_installed_by_make_run()
    assert {"pytest", "hypothesis"} <= hidden
    assert "httpx" not in hidden
    command = [sys.executable, "-c", _RUNNER, str(ROOT / "examples" / example)]
    result = subprocess.run(
        [*command, json.dumps(sorted(hidden)), pilot_url(served)],
        capture_output=True,
        text=True,
        timeout=200,
        check=False,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.count("at north") == 4
    assert "landed" in result.stdout
