"""The fleet edge flies a vehicle on the control core without a web framework: importing
its modules (what a Zenoh call runs through) loads no FastAPI, Starlette or uvicorn."""

from __future__ import annotations

import json
import subprocess
import sys

EDGE_MODULES = (
    "server.fleet.edge", "server.fleet.edge_api", "server.fleet.edge_calls",
    "server.fleet.edge_publish",
)  # fmt: skip
WEB_FRAMEWORKS = ("fastapi", "starlette", "uvicorn")
_LOADED = (
    "import importlib, json, sys\n"
    "for name in {modules!r}: importlib.import_module(name)\n"
    "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in {web!r})))\n"
)


def _web_modules_loaded_by(modules: tuple[str, ...]) -> list[str]:
    code = _LOADED.format(modules=modules, web=WEB_FRAMEWORKS)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, check=True)  # fmt: skip
    loaded: list[str] = json.loads(run.stdout)
    return loaded


def test_the_edge_loads_no_web_framework() -> None:
    assert _web_modules_loaded_by(EDGE_MODULES) == []


def test_the_check_sees_a_web_framework_where_one_is_loaded() -> None:
    assert "fastapi" in _web_modules_loaded_by(("server.http.deps",))
